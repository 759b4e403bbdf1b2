"""One matched frame's three Image messages to a FocalEstimate, without rclpy: the images as
arrays (:func:`msg_adapters.frame_from_images`), the principal point (:mod:`.intrinsics`) and
the estimate. The node's estimator thread calls it and counts what it refuses; the window, the
poses and publishing stay with the node."""
from __future__ import annotations

from msg_adapters import ImageFormatError, ImageSizeMismatch, frame_from_images

from ..core import FocalEstimate, estimate_focal
from .intrinsics import Refused, intrinsics


class FrameRefused(Refused):
    """Images of a frame the estimator cannot read (encoding, size)."""


def estimate_frame(msgs, params: dict, camera_info_in, options, rng) -> FocalEstimate:
    """Estimate the focal length of one (depth, nocs, mask) message set under the node's
    parameter values ``params`` and estimator ``options``, its triplets seeded from ``rng`` (a
    numpy Generator, drawn only for a frame that is estimated); FrameRefused for images of the
    wrong encoding or size, IntrinsicsRefused where no principal point can be had (both are
    :class:`.intrinsics.Refused`)."""
    try:
        depth, nocs, mask = frame_from_images(
            *msgs, params["depth_scale"], params["nocs_convention"])
    except ImageSizeMismatch as exc:
        raise FrameRefused("size_mismatch", str(exc)) from None
    except ImageFormatError as exc:
        raise FrameRefused("bad_encoding", str(exc)) from None
    h, w = depth.shape
    intr = intrinsics(params, camera_info_in, w, h)
    pp_std = tuple(params["principal_point_std"] * size if assumed else 0.0
                   for size, assumed in zip((w, h), intr.assumed))
    return estimate_focal(depth, nocs, mask, (intr.cx, intr.cy), options=options, poses=False,
                          seed=int(rng.integers(2**31)), principal_point_std=pp_std)
