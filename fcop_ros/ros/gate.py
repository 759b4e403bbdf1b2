"""The publish gate: whether the window's focal length goes out as CameraInfo (and may be saved
as a calibration), and if not, why. The node, its diagnostics and ~/save_calibration ask it
alike. Plain logic; no rclpy."""
from __future__ import annotations


def held_back(window, max_uncertainty: float, focal_range: tuple) -> str:
    """Why the window estimate ``window`` (a WindowEstimate) does not go out: '' if it does.
    It needs a focal length within ``focal_range`` (focal_min, focal_max), which may have
    changed at run time, and a ``std_rel`` at most ``max_uncertainty``."""
    if window.focal is None:
        return f"no focal estimate yet: {window.reason}"
    lo, hi = focal_range
    if not lo <= window.focal <= hi:
        return f"focal {window.focal:.1f} px held back: outside focal_range [{lo:g}, {hi:g}]"
    std = getattr(window, "std_rel", None)
    if std is None or std > max_uncertainty:
        shown = "unknown" if std is None else f"{std:.4f}"
        return (f"focal {window.focal:.1f} px held back: std_rel {shown} above "
                f"max_uncertainty {max_uncertainty}")
    return ""
