"""The file ~/save_calibration writes: CameraInfo in the camera_calibration_parsers YAML format
(what camera_info_manager loads), written whole or not at all. No rclpy."""

from __future__ import annotations

import contextlib
import os


def default_calibration_path(camera_name: str) -> str:
    """~/.ros/camera_info/<camera_name>.yaml, where camera_info_manager looks by default."""
    return os.path.expanduser(os.path.join("~", ".ros", "camera_info", f"{camera_name}.yaml"))


def calibration_path(calibration_file: str, camera_name: str) -> str:
    """Where ~/save_calibration writes: ``calibration_file`` (``~`` expanded), else
    camera_info_manager's default for ``camera_name``."""
    if calibration_file:
        return os.path.expanduser(calibration_file)
    return default_calibration_path(camera_name)


def save_calibration(info, std_rel: float, path: str, camera_name: str) -> tuple[bool, str]:
    """Write CameraInfo ``info`` (its estimate's ``std_rel`` for the message) to ``path``:
    (success, the service's message)."""
    try:
        write_calibration(path, info, camera_name)
    except OSError as exc:
        return False, f"cannot write {path}: {exc.strerror or exc}"
    return True, f"saved focal {info.k[0]:.2f} px (std_rel {std_rel:.4f}) to {path}"


def calibration_yaml(info, camera_name: str) -> str:
    """A sensor_msgs/CameraInfo as camera_calibration_parsers YAML."""

    def mat(rows, cols, data):
        values = ", ".join(repr(float(v)) for v in data)
        return f"\n  rows: {rows}\n  cols: {cols}\n  data: [{values}]"

    return (
        f"image_width: {int(info.width)}\nimage_height: {int(info.height)}\n"
        f"camera_name: {camera_name}\n"
        f"camera_matrix:{mat(3, 3, info.k)}\ndistortion_model: {info.distortion_model}\n"
        f"distortion_coefficients:{mat(1, len(info.d), info.d)}\n"
        f"rectification_matrix:{mat(3, 3, info.r)}\nprojection_matrix:{mat(3, 4, info.p)}\n"
    )


def write_calibration(path: str, info, camera_name: str) -> None:
    """Write ``info`` to ``path`` (directories created) through a temporary file and a rename,
    so a reader never sees half a file; raises OSError."""
    os.makedirs(os.path.dirname(path) or ".", exist_ok=True)
    tmp = f"{path}.tmp{os.getpid()}"
    try:
        with open(tmp, "w") as fh:
            fh.write(calibration_yaml(info, camera_name))
        os.replace(tmp, path)
    except BaseException:  # e.g. path is a directory: leave nothing behind
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise
