"""The intrinsics other than f that every CameraInfo carries: the principal point from the
parameters, else from camera_info_in's K, else the image centre (per axis), and camera_info_in's
distortion model, D and R kept as the driver gave them. Plain logic on the node's parameters
and a CameraInfo message; no rclpy."""
from __future__ import annotations

from dataclasses import dataclass

from sensor_msgs.msg import CameraInfo

from msg_adapters import camera_info

from ..core.camera import image_centre, inside_image


class Refused(Exception):
    """Input the node cannot use: ``reason`` is the drop counter's key, the text says why."""

    def __init__(self, reason: str, text: str):
        super().__init__(text)
        self.reason = reason


class IntrinsicsRefused(Refused):
    """No CameraInfo for these images."""


@dataclass(frozen=True)
class Intrinsics:
    """Principal point (px) and, when camera_info_in has a distortion model, D and R."""

    cx: float
    cy: float
    d: tuple | None = None
    distortion_model: str | None = None
    r: tuple | None = None


def intrinsics(params: dict, camera_info_in: CameraInfo | None, width: int,
               height: int) -> Intrinsics:
    """The intrinsics of a ``width`` x ``height`` image, or IntrinsicsRefused when
    camera_info_in is of another size or the principal point lies off the image."""
    cam = camera_info_in
    if cam is not None and cam.width and cam.height and (cam.width, cam.height) != (width,
                                                                                     height):
        raise IntrinsicsRefused(
            "camera_info_size_mismatch",
            f"camera_info_in is {cam.width}x{cam.height}, the images are {width}x{height}",
        )
    use_cam = cam is not None and (cam.k[2] != 0 or cam.k[5] != 0)
    fallback = (cam.k[2], cam.k[5]) if use_cam else image_centre(width, height)
    cx, cy = (
        params[name] if params[name] >= 0 else default
        for name, default in zip(("principal_point_x", "principal_point_y"), fallback)
    )
    if not inside_image(cx, cy, width, height):
        raise IntrinsicsRefused(
            "principal_point_outside",
            f"principal point ({cx}, {cy}) is outside the {width}x{height} image",
        )
    if cam is not None and cam.distortion_model:
        return Intrinsics(float(cx), float(cy), tuple(float(v) for v in cam.d),
                          cam.distortion_model, tuple(float(v) for v in cam.r))
    return Intrinsics(float(cx), float(cy))


def camera_info_with(focal: float, intr: Intrinsics, width: int, height: int,
                     header) -> CameraInfo:
    """REP-104 CameraInfo at ``focal`` with these intrinsics (D, R and the model kept)."""
    info = camera_info(focal, intr.cx, intr.cy, width, height, header)
    if intr.distortion_model is not None:
        info.distortion_model, info.d = intr.distortion_model, list(intr.d)
        if any(intr.r):
            info.r = list(intr.r)
    return info
