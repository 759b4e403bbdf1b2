"""Camera conventions every layer shares, so that each is written once."""
import math
import numbers

import numpy as np


def image_centre(width: int, height: int) -> tuple[float, float]:
    """The principal point assumed when none is given: the image centre, with pixel centres at
    integer coordinates (REP-104 / OpenCV)."""
    return (width - 1) / 2.0, (height - 1) / 2.0


def true_focal(fx: float, fy: float) -> float:
    """The one focal length that a camera of focal lengths ``fx``, ``fy`` (px) is judged
    against: their mean (fcop_ros estimates fx = fy; they differ by 0.14% on REAL275)."""
    return 0.5 * (float(fx) + float(fy))


def inside_image(cx: float, cy: float, width: int, height: int) -> bool:
    """Whether a principal point (cx, cy) lies on the image (pixel centres 0 .. W-1, 0 .. H-1)."""
    return 0 <= cx <= width - 1 and 0 <= cy <= height - 1


def is_number(value) -> bool:
    """A real number and not a bool (True is no coordinate or focal length, nor is text)."""
    return isinstance(value, numbers.Real) and not isinstance(value, (bool, np.bool_))


def checked_principal_point(principal_point, width: int, height: int) -> tuple[float, float]:
    """(cx, cy) as floats, or a ValueError naming what is wrong: anything but two finite real
    numbers (not bools or text) on the image (a principal point off the image is a slip, e.g.
    (cy, cx) or a crop's)."""
    try:
        cx, cy = principal_point
        if not (is_number(cx) and is_number(cy)):
            raise TypeError
        cx, cy = float(cx), float(cy)
    except (TypeError, ValueError):
        raise ValueError(
            f"principal_point must be two numbers (cx, cy) in pixels, got {principal_point!r}"
        ) from None
    if not (math.isfinite(cx) and math.isfinite(cy)):
        raise ValueError(f"principal_point must be finite, got ({cx}, {cy})")
    if not inside_image(cx, cy, width, height):
        raise ValueError(
            f"principal point ({cx}, {cy}) is outside the {width}x{height} image (cx is along "
            "the width, cy along the height)"
        )
    return cx, cy
