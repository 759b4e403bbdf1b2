"""The intrinsics other than f that every CameraInfo carries. fcop_node sees rectified images,
so its output describes the rectified camera (REP-104: K, D and R are the raw camera's, P the
rectified one's, which image_geometry reads for rectified images): the principal point from the
parameters, else camera_info_in's P, else its K, else the image centre (per axis); no distortion,
R the identity; a stereo camera's baseline (P's Tx / fx) kept. Plain logic on the node's
parameters and a CameraInfo message; no rclpy."""
from __future__ import annotations

import copy
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
    """Principal point (px) of the rectified images and, for a stereo camera's second image,
    ``tx_per_f``: camera_info_in's P[0, 3] / P[0, 0] (minus the baseline, metres); ``assumed``:
    per axis, whether the principal point is the image centre for want of anything better."""

    cx: float
    cy: float
    tx_per_f: float = 0.0
    assumed: tuple = (False, False)


def image_window(cam: CameraInfo) -> tuple[int, int, int, int, int, int]:
    """REP-104: the images camera_info_in describes are its ROI of the full-resolution sensor
    (all of it when the ROI is unset), binned ``binning_x`` x ``binning_y`` (0 means 1). Returns
    (x_offset, y_offset, binning_x, binning_y, width, height) of those images."""
    bx, by = max(1, int(cam.binning_x)), max(1, int(cam.binning_y))
    roi = cam.roi
    if roi.width and roi.height:
        x0, y0, w, h = int(roi.x_offset), int(roi.y_offset), int(roi.width), int(roi.height)
    else:
        x0, y0, w, h = 0, 0, int(cam.width), int(cam.height)
    return x0, y0, bx, by, w // bx, h // by


def _principal_point_in(cam: CameraInfo | None, window):
    """camera_info_in's principal point in the images' pixels: P's when P is set, else K's (a
    driver that fills only K), else None; moved by the ROI's offset and divided by the binning
    as image_geometry does (K and P are given at full resolution). ``window``:
    ``image_window(cam)``."""
    if cam is None:
        return None
    if cam.p[0] != 0 and (cam.p[2] != 0 or cam.p[6] != 0):
        cx, cy = float(cam.p[2]), float(cam.p[6])
    elif cam.k[2] != 0 or cam.k[5] != 0:
        cx, cy = float(cam.k[2]), float(cam.k[5])
    else:
        return None
    x0, y0, bx, by, _, _ = window
    return (cx - x0) / bx, (cy - y0) / by


def raw_camera(cam: CameraInfo) -> str:
    """What in camera_info_in describes a raw camera (non-zero D, R other than the identity),
    in words for a warning; '' if nothing does."""
    said = []
    if any(v != 0 for v in cam.d):
        said.append(f"distortion {cam.distortion_model} D={[float(v) for v in cam.d]}")
    if any(cam.r) and any(abs(a - b) > 1e-9 for a, b in zip(cam.r, (1, 0, 0, 0, 1, 0, 0, 0, 1))):
        said.append(f"rectification R={[round(float(v), 6) for v in cam.r]}")
    return " and ".join(said)


def intrinsics(params: dict, camera_info_in: CameraInfo | None, width: int,
               height: int) -> Intrinsics:
    """The intrinsics of a ``width`` x ``height`` image, or IntrinsicsRefused when
    camera_info_in describes images of another size or of unequal binning (pixels not square,
    which fx = fy cannot describe), or the principal point lies off the image."""
    cam = camera_info_in
    window = image_window(cam) if cam is not None else None
    if cam is not None and cam.width and cam.height:
        _, _, bx, by, w, h = window
        if bx != by:
            raise IntrinsicsRefused(
                "camera_info_binning_unequal",
                f"camera_info_in bins {bx}x{by}: the {width}x{height} images' pixels are not "
                "square, and fCOP estimates one focal length for both axes",
            )
        if (w, h) != (width, height):
            said = f"{cam.width}x{cam.height}"
            if (w, h) != (cam.width, cam.height):
                said += f" (images {w}x{h} after its ROI and binning)"
            raise IntrinsicsRefused(
                "camera_info_size_mismatch",
                f"camera_info_in is {said}, the images are {width}x{height}",
            )
    given = _principal_point_in(cam, window)
    fallback = given or image_centre(width, height)
    names = ("principal_point_x", "principal_point_y")
    assumed = tuple(given is None and params[name] < 0 for name in names)
    cx, cy = (
        params[name] if params[name] >= 0 else default
        for name, default in zip(names, fallback)
    )
    if not inside_image(cx, cy, width, height):
        raise IntrinsicsRefused(
            "principal_point_outside",
            f"principal point ({cx}, {cy}) is outside the {width}x{height} image",
        )
    tx_per_f = float(cam.p[3]) / float(cam.p[0]) if cam is not None and cam.p[0] != 0 else 0.0
    return Intrinsics(float(cx), float(cy), tx_per_f, assumed)


def camera_info_with(focal: float, intr: Intrinsics, width: int, height: int,
                     header) -> CameraInfo:
    """REP-104 CameraInfo of the rectified camera at ``focal``: K = P[:, :3], no distortion,
    R = I, and P[0, 3] = focal x ``tx_per_f`` (a stereo pair's baseline kept)."""
    info = camera_info(focal, intr.cx, intr.cy, width, height, header)
    if intr.tx_per_f:
        info.p[3] = float(focal) * intr.tx_per_f
    return info


def at_full_resolution(info: CameraInfo, cam: CameraInfo | None) -> CameraInfo:
    """``info`` (of the images as they come) as a driver's calibration store takes it: REP-104
    calibrations are at the sensor's full resolution, the driver applying its binning and ROI
    on top, so K and P are multiplied by camera_info_in's binning, the principal point moved
    by its ROI offset, and the size is its full size (no binning, no ROI). ``info`` unchanged
    without camera_info_in or when its images are the whole sensor, unbinned."""
    if cam is None or not (cam.width and cam.height):
        return info
    x0, y0, b, _, w, h = image_window(cam)
    if (x0, y0, b, w, h) == (0, 0, 1, cam.width, cam.height):
        return info
    full = copy.deepcopy(info)
    full.width, full.height = int(cam.width), int(cam.height)
    for m, row in ((full.k, 3), (full.p, 4)):
        m[0], m[row + 1] = m[0] * b, m[row + 1] * b
        m[2], m[row + 2] = m[2] * b + x0, m[row + 2] * b + y0
    full.p[3] *= b
    full.binning_x = full.binning_y = 0
    full.roi = type(full.roi)()
    return full
