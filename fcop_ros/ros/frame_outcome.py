"""What one estimated frame did, in the node's words: plain Python, no rclpy.

After the estimator thread has added a frame's FocalEstimate to the tracker, :func:`frame_outcome`
says what to count (dropped frames under the names of the node's ``dropped`` counter, accepted
input that deserved a word under ``warnings``) and what to log. The node only applies that, as it
applies :class:`.intake.SyncStep` on the input side.
"""
from __future__ import annotations

from collections import Counter
from dataclasses import dataclass


@dataclass(frozen=True)
class FrameOutcome:
    """``dropped``: reason -> frames dropped; ``warnings``: reason -> count; ``log``: (level,
    throttle key, line), level 'warn' or 'info' (a change of image size, a zoom), each said at
    most once per throttle period for its key and words; ``kept``: whether the frame reached
    the window."""

    dropped: Counter
    warnings: Counter
    log: tuple
    kept: bool


def frame_outcome(est, step, frame_id: str = "") -> FrameOutcome:
    """What FocalEstimate ``est`` (of a depth image in ``frame_id``) and the tracker's
    :class:`.tracker.TrackStep` ``step`` mean."""
    dropped, warnings, log = Counter(), Counter(), []
    w, h = est.image_size
    if est.mirrored:
        warnings["mirrored_nocs"] += len(est.mirrored)
        log.append(("warn", "mirrored_nocs",
                    f"the NOCS of instance(s) {est.mirrored} fit their shape only as a "
                    "mirror image: is the nocs image's channel order right (rgb8 vs bgr8), or its "
                    "axis convention (parameter nocs_convention)? The focal length is "
                    "unaffected; no pose is published for them"))
    if step.kept_size is not None:
        kw, kh = step.kept_size
        if step.kept_size == (w, h):  # the same size: another camera frame
            dropped["other_frame_id_no_evidence"] += 1
            log.append(("warn", "other_frame_id_no_evidence",
                        f"dropped a frame in {frame_id!r} without focal evidence "
                        f"({est.reason}); the window keeps its frames in "
                        f"{step.kept_frame_id!r}"))
        else:
            dropped["other_size_no_evidence"] += 1
            log.append(("warn", "other_size_no_evidence",
                        f"dropped a {w}x{h} frame without focal evidence ({est.reason}); "
                        f"the window keeps its {kw}x{kh} frames"))
        return FrameOutcome(dropped, warnings, tuple(log), False)
    if est.focal is None:
        dropped["no_evidence"] += 1
        log.append(("warn", "no_evidence",
                    f"frame without focal evidence: {est.reason}"))
    if step.resized_from is not None:
        ow, oh = step.resized_from
        log.append(("info", "resized", f"image size changed from {ow}x{oh} to "
                                        f"{w}x{h}: new focal window"))
    if step.reframed_from is not None:
        warnings["frame_id_changed"] += 1
        log.append(("warn", "frame_id_changed",
                     f"the depth images' frame_id changed from {step.reframed_from!r} to "
                     f"{frame_id!r} (another camera?): new focal window"))
    win = step.window_estimate
    if win.changed:
        at = "no focal yet" if win.focal is None else f"{win.focal:.1f} px"
        log.append(("info", "zoom", "focal length changed (zoom?): " + (
            "window restarted" if win.zoom is None else
            f"x{win.zoom:.3f} as the objects' image sizes show; the window keeps its "
            f"{win.frames} frames at the new focal") + f", now at {at}"))
    return FrameOutcome(dropped, warnings, tuple(log), True)
