"""Frame-wise focal length estimate (fCOP-IS, then a per-object maximum-likelihood fit) and poses.

Pipeline: per-instance correspondences -> random triplets on every object -> minimal solver
votes -> interval stabbing over the votes of all objects (the paper's frame-wise consistency:
the starting focal length and the evidence threshold) -> every object's own focal length from
a fit in which depth errors enter linearly (:mod:`.object_fit`) -> objects whose NOCS do not
explain their shape are refused -> a combination of the objects' focal lengths
(:mod:`.combine`), whose spread gives ``std_rel`` -> the focal range -> each object's pose at
the combined focal length. ``method="ransac"`` replaces stabbing by the paper's RANSAC variant;
``refine=False`` stops at the stabbed votes (the paper's method).
"""

from __future__ import annotations

import math
import sys

from dataclasses import dataclass, field

import numpy as np

from . import compiled
from .combine import combine_objects
from .camera import checked_principal_point, image_centre, is_number
from .correspondences import (
    NOCS_TOLERANCE,
    Instance,
    _mask_bytes,
    _mean,
    _median_k,
    calibrated_nocs,
    check_images,
    extract_instances,
    nocs_range,
    nocs_range_hint,
)
from .error_model import depth_influence, object_variances
from .lens import lens_gradients
from .object_fit import _plain_rows, fit_objects
from .pose import ObjectPose, umeyama
from .offsets import IntrinsicsEvidence, offset_information, offset_posterior
from .principal_point import focal_gradients
from .solver import object_votes, solve_triplets
from .options import EstimatorOptions
from .stabbing import interval_stabbing, stab_equal_width


#: The options of a call without any (frozen, so one instance serves every frame).
_DEFAULT_OPTIONS = EstimatorOptions()
# The objects' median depth, metres, of a scene estimate_focal takes: 10 cm to 1 km in metres,
# millimetres or kilometres. The fits' noise floors are in metres: at 1e-5 of a frame's depth its
# std_rel drifted (-55% on clean_frame(1)), at 1e-9 its focal (+71%); from 1e10 on, the focal of
# noisy_frame(3, "harsh") drifted (+0.04%, +4% at 1e15), and 1e300 raised OverflowError.
DEPTH_RANGE = (1e-4, 1e6)


@dataclass(eq=False)
class FocalEstimate:
    """Result of :func:`estimate_focal`.

    focal: focal length in pixels (fx = fy), or None when the frame gives no evidence (then
    ``reason`` says why). std_rel: relative standard error of focal (from the objects' fits and
    their disagreement). std_rel_noise: the part of std_rel that pixel noise makes, which a new
    frame draws anew (the rest, from shape mismatch, unseen depth error and the objects'
    disagreement, repeats while the same objects are in view). std_rel_prior: the part of
    std_rel that stands in for the disagreement a frame of few objects cannot show (the prior
    spread ``object_tau``; a frame of one object pays it whole). std_rel_principal_point: the
    part of std_rel that the principal point's uncertainty makes (none where it is given; the
    frame's objects move f with it, each by its own gradient, and it persists from frame to
    frame). std_rel_lens: the part of std_rel that the uncertainty of a residual radial
    distortion k1 of the rectified image makes (prior ``lens_distortion_std``; each object's f
    moves with k1 by its own gradient, :mod:`.lens`, and one k1 persists from frame to frame).
    principal_point_offset: (dx, dy) px, where the objects' disagreement puts an assumed
    principal point relative to it (their focal lengths are corrected by it; None where
    the principal point is given). lens_k1: the k1 the objects' disagreement shows (their
    focal lengths are corrected by it; None where ``lens_distortion_std`` is 0).
    intrinsics_evidence: what the frame's objects say of those offsets (:mod:`.offsets`), which
    a :class:`~.window.FocalWindow` pools over its frames (None where neither is estimated).
    focal_votes: the stabbed value of the triplet votes.
    interval: (lo, hi) focal range in pixels of the maximal consensus region. inlier_count /
    inlier_ratio: votes agreeing with it. votes_per_object / inliers_per_object:
    {instance_id: count}. object_focals: {instance_id: (focal, std_rel, std_rel_noise)} of the
    objects combined; rejected: {instance_id: why} of instances not used; mirrored: instance ids
    whose NOCS fit only as a reflection (channel order or axis convention); instances_skipped:
    instances beyond ``max_instances`` (the smallest), not used; objects: poses of the combined,
    unmirrored objects when ``estimate_focal`` ran the pose stage (see :mod:`.pose`); votes: all
    valid triplet votes (px);
    instances: the :class:`~.correspondences.Instance` s of the combined objects whose own
    std_rel is within ``pose_max_std`` (those that can be posed), the input of the pose stage:
    ``estimate_poses(est.instances, focal, exclude=est.mirrored)`` at any focal length, e.g. a
    window's. object_extents: {instance_id: image scale x median depth (px m per NOCS unit)}
    of all the combined objects, where the image scale is the object's RMS image radius over
    the RMS radius of its NOCS: the focal length times the object's size (metres per NOCS
    unit), whatever part of it is in view. A zoom scales it; moving the camera or the object
    does not (the depth makes up for the image size), nor does an occlusion or the image's
    edge (pixels and NOCS go together), so the window tells a zoom from frames whose errors
    moved by it. object_radii: the same objects' image scale alone (px per NOCS unit),
    which a depth network's frame-to-frame change of scale does
    not move. image_size: (width, height), as in CameraInfo (numpy's shape is (height, width)).
    std_rel and std_rel_noise are None where the estimate has no per-object fit to draw them
    from: ``method="ransac"``, ``refine=False``, ``PAPER_FCOP_IS``. Two estimates compare equal
    only if they are the same object.
    """

    focal: float | None
    principal_point: tuple[float, float]
    image_size: tuple[int, int]
    inlier_count: int = 0
    inlier_ratio: float = 0.0
    interval: tuple[float, float] | None = None
    focal_votes: float | None = None
    std_rel: float | None = None
    std_rel_noise: float | None = None
    std_rel_prior: float | None = None
    std_rel_principal_point: float | None = None
    std_rel_lens: float | None = None
    principal_point_offset: tuple[float, float] | None = None
    lens_k1: float | None = None
    intrinsics_evidence: IntrinsicsEvidence | None = field(default=None, repr=False)
    votes_per_object: dict = field(default_factory=dict)
    inliers_per_object: dict = field(default_factory=dict)
    object_focals: dict = field(default_factory=dict)
    rejected: dict = field(default_factory=dict)
    mirrored: list = field(default_factory=list)
    objects: list = field(default_factory=list)
    votes: np.ndarray = field(default_factory=lambda: np.zeros(0))
    method: str = "stabbing"
    reason: str = ""
    instances_skipped: int = 0
    instances: list = field(default_factory=list, repr=False)
    object_extents: dict = field(default_factory=dict)
    object_radii: dict = field(default_factory=dict)


# NOCS spread below which an object's image scale is not told apart from none (objects whose
# NOCS are flat are refused long before: _FLAT).
_MIN_NOCS_RADIUS = 1e-6


def _image_scale_depth(inst: Instance) -> tuple[float, float]:
    """The instance's image scale, its pixels' RMS image radius about their centroid over their
    NOCS' RMS radius about theirs (px per NOCS unit), and its median depth (m). A zoom scales it;
    a part of the object hidden (occlusion) takes pixels and NOCS alike and leaves it."""
    if compiled.ENABLED and all(a.dtype == np.float64 for a in (inst.x, inst.d, inst.p)):
        r, d = _image_scale_depth_kernel(np.ascontiguousarray(inst.x), inst.d,
                                         np.ascontiguousarray(inst.p))
        return float(r), float(d)
    r = inst.x - inst.x.mean(0)
    q = inst.p - inst.p.mean(0)
    rn = max(float(np.sqrt(np.mean((q * q).sum(1)))), _MIN_NOCS_RADIUS)
    return float(np.sqrt(np.mean(r[:, 0] ** 2 + r[:, 1] ** 2))) / rn, float(np.median(inst.d))


@compiled.kernel
def _image_scale_depth_kernel(x, d, p):
    """``_image_scale_depth`` in two passes over x and p and a selection of d's median (numpy's
    few calls on an axis of two or three cost more than the arithmetic)."""
    n = x.shape[0]
    m0 = m1 = 0.0
    q0 = q1 = q2 = 0.0
    for r in range(n):
        m0 += x[r, 0]
        m1 += x[r, 1]
        q0 += p[r, 0]
        q1 += p[r, 1]
        q2 += p[r, 2]
    m0, m1, q0, q1, q2 = m0 / n, m1 / n, q0 / n, q1 / n, q2 / n
    s = 0.0
    sn = 0.0
    for r in range(n):
        u, v = x[r, 0] - m0, x[r, 1] - m1
        s += u * u + v * v
        a, b, c = p[r, 0] - q0, p[r, 1] - q1, p[r, 2] - q2
        sn += a * a + b * b + c * c
    rn = max(np.sqrt(sn / n), _MIN_NOCS_RADIUS)
    return np.sqrt(s / n) / rn, (_median_k(d.copy(), d.size) if d.size else np.nan)


def _no_instance_reason(depth, nocs, mask, opt: EstimatorOptions) -> str:
    """Why no instance was usable, naming the input that lacks what it needs (an empty mask,
    no valid depth or no NOCS prediction on the objects, NOCS outside [0, 1]) before the pixel
    count."""
    on = mask > 0
    if not on.any():
        return "the mask has no instance (no id above 0)"
    d = depth[on]
    depth_ok = np.isfinite(d) & (d > 0)
    if not depth_ok.any():
        return "the depth is invalid (NaN, inf or <= 0) on every object pixel"
    p = nocs[on]
    predicted = np.isfinite(p).all(1) & (p != 0).any(1)
    if not predicted.any():
        return "the NOCS are zero or not finite (no prediction) on every object pixel"
    reason = f"no instance with >= {opt.min_object_pixels} valid pixels"
    valid = mask[on][depth_ok & predicted]
    most = int(np.unique(valid, return_counts=True)[1].max()) if valid.size else 0
    if opt.erode_px > 0 and most >= opt.min_object_pixels:
        reason += (f" after eroding each mask by erode_px={opt.erode_px} (the largest had {most}"
                   " before: a small or thin object; lower erode_px)")
    if opt.min_object_pixels > opt.max_pixels:
        reason += (f" (min_object_pixels={opt.min_object_pixels} is above max_pixels="
                   f"{opt.max_pixels}, about what a large object keeps: lower min_object_pixels)")
    top = float(np.max(p[predicted]))
    low = float(np.min(p[predicted]))
    if top > 1 + NOCS_TOLERANCE or low < -NOCS_TOLERANCE:
        reason += f" ({nocs_range_hint(low, top, nocs.dtype)})"
    return reason


def _frame_checks(depth, nocs, mask):
    """nocs_range's (share, sampled, low, high) and _object_depth's median depth of one frame,
    from the same sampled pixels: by one compiled pass where the kernels run (the two numpy
    passes cost ~0.1 ms at 640x480, each reading the strided images from memory)."""
    if not (compiled.ENABLED and mask.dtype.isnative and sys.byteorder == "little"
            and mask.size and depth.dtype == nocs.dtype
            and depth.dtype in (np.float32, np.float64)):
        return (*nocs_range(nocs, mask), _object_depth(depth, mask))
    kind = nocs.dtype.type  # nocs_range compares in the image's type (NEP 50)
    n_pred, n_out, low, high, level, n_depth = _frame_checks_kernel(
        _mask_bytes(mask), mask.dtype.itemsize, mask.dtype.kind == "i", depth, nocs, _CHECK_STRIDE,
        kind(-NOCS_TOLERANCE), kind(1 + NOCS_TOLERANCE))
    share = (0.0, 0, 0.0, 0.0) if n_pred == 0 else (n_out / n_pred, int(n_pred), float(low),
                                                      float(high))
    return (*share, float(level) if n_depth else _object_depth(depth, mask))


_CHECK_STRIDE = 8  # nocs_range's and _object_depth's sampling: every 8th row and column


@compiled.kernel
def _frame_checks_kernel(raw, itemsize, signed, depth, nocs, stride, lo_b, hi_b):
    """(NOCS predictions sampled, how many out of [lo_b, hi_b], their smallest and largest
    value, the median sampled depth, the depths sampled): nocs_range and _object_depth on the
    object pixels of every ``stride``-th row and column of the mask's bytes ``raw``
    (``_mask_bytes`` of a little-endian mask: one signature for every integer type). A pixel is
    an object's if any of its bytes is set and, of a ``signed`` type, not its sign bit."""
    h = raw.shape[0]
    w = raw.shape[1] // itemsize
    dbuf = np.empty(((h + stride - 1) // stride) * ((w + stride - 1) // stride), depth.dtype)
    n_pred = 0
    n_out = 0
    n_depth = 0
    low = np.inf
    high = -np.inf
    for y in range(0, h, stride):
        row = raw[y]
        for x in range(0, w, stride):
            at = x * itemsize
            if signed and row[at + itemsize - 1] & 0x80:  # a negative id: background
                continue
            nonzero = False
            for q in range(itemsize):
                nonzero |= row[at + q] != 0
            if not nonzero:
                continue
            d = depth[y, x]
            if np.isfinite(d) and d > 0:
                dbuf[n_depth] = d
                n_depth += 1
            a, b, c = nocs[y, x, 0], nocs[y, x, 1], nocs[y, x, 2]
            lo = min(a, b, c)
            hi = max(a, b, c)
            if not (np.isfinite(a) and np.isfinite(b) and np.isfinite(c)) or (lo == 0 and hi == 0):
                continue
            n_pred += 1
            n_out += (lo < lo_b) | (hi > hi_b)
            low = min(low, lo)
            high = max(high, hi)
    level = np.median(dbuf[:n_depth]) if n_depth else 0.0
    return n_pred, n_out, low, high, level, n_depth


def _object_depth(depth, mask, stride: int = _CHECK_STRIDE):
    """The median valid depth on the object pixels of every ``stride``-th row and column (on
    all object pixels if those have none; None if no object pixel has one): ~50 us at 640x480,
    so that every frame's depth is checked against DEPTH_RANGE."""
    d = depth[::stride, ::stride][mask[::stride, ::stride] > 0]
    d = d[np.isfinite(d) & (d > 0)]
    if not d.size:
        d = depth[mask > 0]
        d = d[np.isfinite(d) & (d > 0)]
    return float(np.median(d)) if d.size else None


def _votes(instances: list[Instance], opt: EstimatorOptions, rng: np.random.Generator):
    """Minimal-solver votes of every object, solved in one call: (focal (V,), owner index (V,))."""
    return object_votes([inst.x for inst in instances], [inst.d for inst in instances],
                        [inst.p for inst in instances], int(opt.triplets_per_object), rng,
                        opt.focal_range)


def _no_vote_reason(instances, opt: EstimatorOptions, rng, state) -> str:
    """Why no triplet voted: the same triplets (drawn again from the generator ``state`` they
    were drawn from, on a copy: nothing else sees it) solved without focal_range tell votes
    that all fell outside the range from degenerate geometry."""
    again = np.random.Generator(type(rng.bit_generator)())
    again.bit_generator.state = state
    votes, _ = object_votes([inst.x for inst in instances], [inst.d for inst in instances],
                            [inst.p for inst in instances], int(opt.triplets_per_object), again,
                            (0.0, np.inf))
    if votes.size == 0:
        return "no valid triplet (degenerate geometry)"
    lo, hi = opt.focal_range
    return (
        f"all {votes.size} focal votes outside focal_range [{lo:g}, {hi:g}] "
        f"(median {np.median(votes):.1f} px)"
    )


def _nocs_spread(p: np.ndarray):
    """RMS distance of NOCS points p (N,3) from their mean: sqrt(mean(sum((p - mean)^2, axis=1))),
    written per column (the same bits; numpy reduces an axis of 3 slowly) or compiled."""
    if compiled.ENABLED and p.dtype == np.float64:
        return _nocs_spread_kernel(np.ascontiguousarray(p))
    m = p.mean(0)
    s = (p[:, 0] - m[0]) ** 2
    s += (p[:, 1] - m[1]) ** 2
    s += (p[:, 2] - m[2]) ** 2
    return np.sqrt(s.mean())


@compiled.kernel
def _nocs_spread_kernel(p):
    """``_nocs_spread`` in one pass with numpy's bits: the column means summed in order, as
    numpy reduces axis 0, and the mean of the squared distances in numpy's pairwise order
    (sequential below 8, eight accumulators up to 128, halves above; the halving recursion
    runs on an explicit stack)."""
    n = p.shape[0]
    m0 = m1 = m2 = 0.0
    for r in range(n):
        m0 += p[r, 0]
        m1 += p[r, 1]
        m2 += p[r, 2]
    m0, m1, m2 = m0 / n, m1 / n, m2 / n
    s = np.empty(n)
    for r in range(n):
        u, v, w = p[r, 0] - m0, p[r, 1] - m1, p[r, 2] - m2
        s[r] = u * u + v * v + w * w
    # Stack entries (offset, length, combine?): a block is summed, split, or, once both its
    # halves are on the value stack, their sum replaces them (left + right, as numpy adds).
    offs, lens, combine = np.empty(64, np.intp), np.empty(64, np.intp), np.empty(64, np.bool_)
    vals = np.empty(64)
    offs[0], lens[0], combine[0] = 0, n, False
    top, vtop = 1, 0
    while top > 0:
        top -= 1
        off, ln = offs[top], lens[top]
        if combine[top]:
            vals[vtop - 2] = vals[vtop - 2] + vals[vtop - 1]
            vtop -= 1
        elif ln < 8:
            res = 0.0
            for i in range(off, off + ln):
                res += s[i]
            vals[vtop] = res
            vtop += 1
        elif ln <= 128:
            r = s[off:off + 8].copy()
            i = 8
            while i < ln - ln % 8:
                for j in range(8):
                    r[j] += s[off + i + j]
                i += 8
            res = ((r[0] + r[1]) + (r[2] + r[3])) + ((r[4] + r[5]) + (r[6] + r[7]))
            while i < ln:
                res += s[off + i]
                i += 1
            vals[vtop] = res
            vtop += 1
        else:
            half = ln // 2
            half -= half % 8
            offs[top], lens[top], combine[top] = off, ln, True
            offs[top + 1], lens[top + 1], combine[top + 1] = off + half, ln - half, False
            offs[top + 2], lens[top + 2], combine[top + 2] = off, half, False  # summed first
            top += 3
    return np.sqrt(vals[0] / n)


# An object whose back-projected pixels spread across their thinnest axis by at least _SOLID
# of their extent is a solid; its NOCS must then spread by at least _FLAT of that ratio.
# Measured with this code on tuning-model frames (seeds 66000-66149; 1147 `predicted` and
# `sensor` objects): the NOCS over pixels ratio of `predicted` objects has a 10th percentile of
# 0.73 at the true focal length (0.60-1.14 at half and twice it), and no object is refused; with
# one NOCS channel constant, 462 of 635 objects are. A face seen head-on whose mask takes in a
# rim of the object's sides reads as solid up to 0.15 (a sensor scene, seed 41), so _SOLID
# stays above that.
_SOLID = 0.2
_FLAT = 0.25
# Per-pixel NOCS noise (Instance.sigma_p) of an object refused for its small span that names the
# NOCS noise, not a shape: `predicted` objects read at most 0.016, random and shuffled NOCS
# 0.16-0.34 (8 frames each, test_world_accuracy's seeds). It words the reason only.
_NOISE_NOT_SHAPE = 0.1


def _flatness(instances, focal: float, points: int = 200):
    """(O, 2, 2) the square roots of the smallest and the middle over the largest principal
    variance ([..., 0] and [..., 1]), of each object's NOCS ([:, 0]; their noise taken off)
    and of its pixels back-projected at ``focal`` ([:, 1]; the depth noise taken off their
    depth variance), from
    every step-th pixel, at most ``points`` of them. A similarity keeps these ratios, a wrong
    focal length changes them by a bounded factor; NOCS with a constant or lost channel are
    flatter than the object their depth shows."""
    covs = np.empty((len(instances), 2, 3, 3))
    focal = float(focal)
    fast = compiled.ENABLED
    for k, inst in enumerate(instances):
        x, d, p = inst.x, inst.d, inst.p
        step = max(1, -(-len(d) // points))
        if fast and _plain_rows(x, d, p):
            _moments_kernel(x, d, p, step, focal, covs[k])
        else:
            covs[k] = _moments(x[::step], d[::step], p[::step], focal)
        covs[k, 1, 2, 2] -= _mean(inst.var_d) if len(inst.var_d) else 0.0
        if inst.var_p is not None and len(inst.var_p):
            covs[k, 0] -= _mean(inst.var_p) * np.eye(3)
    ev = np.clip(np.linalg.eigvalsh(covs), 0.0, None)  # ascending
    return np.sqrt(ev[..., :2] / np.maximum(ev[..., 2:], 1e-300))


def _moments(x, d, p, focal: float):
    """(2, 3, 3) the covariance of the NOCS p and of the pixels x at depth d back-projected at
    ``focal``."""
    pts = np.empty((2, len(d), 3))
    pts[0] = p
    pts[1, :, :2] = x * (d / focal)[:, None]
    pts[1, :, 2] = d
    c = pts - pts.mean(1, keepdims=True)
    return np.swapaxes(c, 1, 2) @ c / max(len(d), 1)


@compiled.kernel
def _moments_kernel(x, d, p, step, focal, out):
    """``_moments`` of every step-th pixel, into ``out``, in two passes without the copies (each
    numpy call on an axis of three costs more than its arithmetic)."""
    n = (d.shape[0] + step - 1) // step
    out[:] = 0.0
    if n == 0:
        return
    mean = np.zeros((2, 3))
    v = np.empty((2, 3))
    for r in range(0, d.shape[0], step):
        for c in range(3):
            mean[0, c] += p[r, c]
        mean[1, 0] += x[r, 0] * d[r] / focal
        mean[1, 1] += x[r, 1] * d[r] / focal
        mean[1, 2] += d[r]
    for j in range(2):
        for c in range(3):
            mean[j, c] /= n
    for r in range(0, d.shape[0], step):
        for c in range(3):
            v[0, c] = p[r, c] - mean[0, c]
        v[1, 0] = x[r, 0] * d[r] / focal - mean[1, 0]
        v[1, 1] = x[r, 1] * d[r] / focal - mean[1, 1]
        v[1, 2] = d[r] - mean[1, 2]
        for j in range(2):
            for a in range(3):
                for b in range(3):
                    out[j, a, b] += v[j, a] * v[j, b]
    for j in range(2):
        for a in range(3):
            for b in range(3):
                out[j, a, b] /= n


def _constant_channel(instances, tolerance: float = 0.01, points: int = 200):
    """(channel, value) of a NOCS channel whose standard deviation over every object's pixels
    (every step-th, at most ``points`` per object) is below ``tolerance`` while another's is 3
    times that or more (a lost channel: an object's own NOCS span 0.1 or more), or None."""
    p = np.concatenate([inst.p[::max(1, -(-len(inst.p) // points))] for inst in instances])
    std = p.std(0)
    c = int(np.argmin(std))
    # All three channels nearly constant is a piece too small to tell, not a channel lost.
    lost = std[c] < tolerance and np.max(std) >= 3 * tolerance
    return (c, float(np.median(p[:, c]))) if lost else None


def _lost_text(lost) -> str:
    """The words for a (channel, value) of :func:`_constant_channel`."""
    return f"NOCS channel {lost[0]} is {lost[1]:.3f} on every object"


def _lost_channel_hint(instances) -> str:
    """For a frame refused before the objects' fits: a note naming a NOCS channel constant on
    every object (a dead network output or an image that lost a channel), or ''."""
    lost = _constant_channel(instances)
    return "" if lost is None else f"; {_lost_text(lost)}: a lost channel?"


def _noise_reason(inst) -> str:
    """Why an object whose NOCS are noise (``sigma_p`` >= _NOISE_NOT_SHAPE) is no shape."""
    return (f"its NOCS vary by {inst.sigma_p:.2f} from pixel to pixel: noise, not a shape "
            "(random or shuffled NOCS?)")


def _quality_reason(quality: float, least: float) -> str:
    """Why an object whose NOCS explain ``quality`` of its shape is refused by min_fit_quality
    ``least``: the share rounded down, so that it never reads as the threshold, and the setting
    blamed when the default would keep the object."""
    head = f"its NOCS explain {math.floor(quality * 1000) / 10:.1f}% of its shape"
    if quality >= _DEFAULT_OPTIONS.min_fit_quality:
        return (f"{head}, below min_fit_quality={least:g} (the default "
                f"{_DEFAULT_OPTIONS.min_fit_quality:g} keeps it): lower min_fit_quality")
    return f"{head}, below min_fit_quality={least:g}: not the predicted category"


def _flat_reason(ratios) -> str | None:
    """Why an object's NOCS are refused as flatter than its depth shows, or None."""
    nocs, pixels = ratios[:, 0]
    if pixels > _SOLID and nocs < _FLAT * pixels:
        return (
            f"its NOCS are flat ({nocs:.2f} of their extent across their thinnest axis) where "
            f"its depth shows a solid ({pixels:.2f}): a NOCS channel constant or lost?"
        )
    return None


def estimate_poses(
    instances, focal: float, *, exclude=(), rng: np.random.Generator | None = None
) -> list[ObjectPose]:
    """The pose stage: the pose of each instance at ``focal`` (e.g. a window's focal length).

    instances: items with instance_id, x, d, p (a :class:`FocalEstimate`'s ``instances``: the
    objects that made its estimate); exclude: instance ids to leave out (its ``mirrored``).
    Each pose is the maximum-likelihood similarity (reprojection and depth residuals) at the
    fixed focal length, all instances fitted in one batch; instances whose NOCS fit only as a
    reflection get none. ``rng`` draws the fit's pixel subsets (default: a fixed seed).
    """
    if not is_number(focal):
        raise TypeError(f"focal must be a number of pixels, got {focal!r}")
    focal = float(focal)
    if not (np.isfinite(focal) and focal > 0):
        raise ValueError(f"focal must be a finite number of pixels > 0, got {focal}")
    if not instances:
        return []
    fits = fit_objects(instances, focal, fix_focal=True, proper=True, iterations=6, rng=rng)
    skip = set(exclude or ())
    return [
        ObjectPose(
            inst.instance_id,
            fits.rotation[k],
            fits.translation[k],
            float(fits.scale[k]),
            float(fits.inlier_ratio[k]),
            float(fits.sigma_depth[k]),
            int(len(inst.d)),
        )
        for k, inst in enumerate(instances)
        if fits.ok[k]
        and not fits.mirrored[k]
        and np.linalg.det(fits.rotation[k]) > 0
        and inst.instance_id not in skip
    ]


def _ransac(instances, opt, rng):
    """The paper's fCOP-RANSAC: a triplet gives f and, by Umeyama on its three points, a pose;
    the hypothesis with most pixels within ``ransac_threshold`` of its object wins. The paper's
    threshold is in metres; here it is relative to the object's median depth (0.005: 5 mm at
    1 m), so that a depth in other units, or a depth network's global scale, leaves f alone."""
    lo, hi = opt.focal_range
    nh = int(opt.ransac_hypotheses)
    owner = rng.integers(0, len(instances), nh)
    counts = np.array([len(i.d) for i in instances])
    nmax = int(min(counts.max(), 1000))
    # Padded per-object arrays (O, nmax) for vectorised scoring.
    X = np.zeros((len(instances), nmax, 2))
    D = np.ones((len(instances), nmax))
    P = np.zeros((len(instances), nmax, 3))
    M = np.zeros((len(instances), nmax), dtype=bool)
    for k, inst in enumerate(instances):
        m = min(len(inst.d), nmax)
        pick = rng.choice(len(inst.d), m, replace=False)
        X[k, :m], D[k, :m], P[k, :m], M[k, :m] = inst.x[pick], inst.d[pick], inst.p[pick], True
    n_o = np.minimum(counts, nmax)
    # Distinct triplet indices per hypothesis within its object's valid range.
    u = rng.random((nh, 3))
    idx = np.floor(u * n_o[owner, None]).astype(int)
    bad = (idx[:, 0] == idx[:, 1]) | (idx[:, 1] == idx[:, 2]) | (idx[:, 0] == idx[:, 2])
    xs, ds, ps = X[owner[:, None], idx], D[owner[:, None], idx], P[owner[:, None], idx]
    f = np.zeros(nh)
    ok = ~bad
    m = int(ok.sum())
    if m:
        # Each hypothesis' three points laid out consecutively, so triplet k is (3k, 3k+1, 3k+2).
        fv, _, okv = solve_triplets(
            xs[ok].reshape(-1, 2),
            ds[ok].reshape(-1),
            ps[ok].reshape(-1, 3),
            np.arange(3 * m).reshape(-1, 3),
        )
        f[ok] = fv
        ok[ok] = okv
    ok &= (f >= lo) & (f <= hi)
    if not ok.any():
        return None, 0, np.zeros(nh, dtype=bool)
    h = np.flatnonzero(ok)
    fh = f[h][:, None]
    tri_pts = np.concatenate([xs[h] / fh[..., None] * ds[h][..., None], ds[h][..., None]], axis=-1)
    s, R, t = umeyama(ps[h] - 0.5, tri_pts)
    Xo = X[owner[h]]
    pts = np.concatenate(
        [Xo / fh[..., None] * D[owner[h]][..., None], D[owner[h]][..., None]], axis=-1
    )
    pred = s[:, None, None] * np.einsum("hij,hnj->hni", R, P[owner[h]] - 0.5) + t[:, None, :]
    res = np.linalg.norm(pts - pred, axis=-1)
    depth_median = np.array([np.median(inst.d) for inst in instances])
    near = res < opt.ransac_threshold * depth_median[owner[h]][:, None]
    score = (near & M[owner[h]]).sum(1) / np.maximum(n_o[owner[h]], 1)
    best = int(np.argmax(score))
    return float(f[h[best]]), int(round(score[best] * n_o[owner[h[best]]])), owner


def estimate_focal(
    depth,
    nocs,
    mask,
    principal_point=None,
    options: EstimatorOptions | None = None,
    *,
    seed=None,
    poses: bool = True,
    principal_point_std=None,
) -> FocalEstimate:
    """Estimate the focal length (pixels, fx = fy) of one frame and the poses of its objects.

    Args:
        depth: (H,W) z-depth in metres; NaN, inf and <= 0 are invalid. A global scale error of
            the depth does not change the focal length (it goes into the object scale); a frame
            whose objects' median depth is outside DEPTH_RANGE (1e-4 .. 1e6 m) is refused.
        nocs: (H,W,3) NOCS in [0,1]; all-zero pixels have no prediction.
        mask: (H,W) integer instance ids, 0 = background.
        principal_point: (cx, cy) pixels; default ((W-1)/2, (H-1)/2).
        principal_point_std: (sx, sy) pixels, how far the principal point may be off; default
            none for a given ``principal_point``, ``options.principal_point_std`` of the
            image's width and height for the assumed centre. The prior of the offset the
            objects' disagreement shows: f is corrected by that offset, and std_rel widened
            by what remains uncertain of it (0: neither).
        options: an :class:`EstimatorOptions` (default: fcop_ros's settings;
            ``PAPER_FCOP_IS``: the paper's method taken literally).
        seed: of the random triplets and pixel subsets (None: from the OS).
        poses: also run the pose stage (:func:`estimate_poses`) at the frame's focal length;
            False leaves it to the caller, e.g. at a window's focal length.

    Returns a :class:`FocalEstimate`; ``focal`` is None when there is no evidence, never a
    made-up number. Mismatched or malformed images, and a principal point off the image,
    raise ValueError; options not passed as ``options=EstimatorOptions(...)`` raise TypeError.
    """
    opt = _DEFAULT_OPTIONS if options is None else options
    if not isinstance(opt, EstimatorOptions) or isinstance(principal_point, EstimatorOptions):
        raise TypeError("estimate_focal takes its settings as options=EstimatorOptions(...)")
    depth, nocs, mask = check_images(depth, nocs, mask)
    h, w = depth.shape
    pp = (
        image_centre(w, h) if principal_point is None
        else checked_principal_point(principal_point, w, h)
    )
    pp_std = _principal_point_std(principal_point, principal_point_std, opt, w, h)
    rng = np.random.default_rng(seed)
    base = dict(principal_point=pp, image_size=(w, h), method=opt.method)
    share, sampled, low, high, level = _frame_checks(depth, nocs, mask)
    if sampled >= 20 and share > 0.2:
        return FocalEstimate(None, reason=(
            f"NOCS outside [0, 1] on {share:.0%} of the object pixels sampled "
            f"({nocs_range_hint(low, high, nocs.dtype)})"), **base)
    if level is not None and not DEPTH_RANGE[0] <= level <= DEPTH_RANGE[1]:
        return FocalEstimate(None, reason=(
            f"the objects' median depth is {level:.3g} m, outside {DEPTH_RANGE[0]:g} .. "
            f"{DEPTH_RANGE[1]:g} m: depth must be in metres (another unit, or a wrong scale?)"),
            **base)
    instances = extract_instances(
        depth,
        nocs,
        mask,
        pp,
        min_object_pixels=opt.min_object_pixels,
        erode_px=opt.erode_px,
        denoise_radius=opt.denoise_radius,
        outlier_sigma=opt.outlier_sigma,
        edge_sigma=opt.edge_sigma,
        max_pixels=opt.max_pixels,
        max_instances=opt.max_instances,
        rng=rng,
    )
    if not instances:
        return FocalEstimate(None, reason=_no_instance_reason(depth, nocs, mask, opt), **base)
    base["instances_skipped"] = getattr(instances, "skipped", 0)

    if opt.method == "ransac":
        f, support, _ = _ransac(instances, opt, rng)
        if f is None:
            return FocalEstimate(None, reason="no valid RANSAC hypothesis", **base)
        if support == 0:
            return FocalEstimate(None, reason=(
                "no RANSAC hypothesis has a pixel within ransac_threshold "
                f"({opt.ransac_threshold:g} of the object's depth) of its object"), **base)
        return _finish(
            FocalEstimate(None, inlier_count=support, focal_votes=f, **base),
            f,
            None,
            instances,
            opt,
            rng,
            poses,
        )

    drawn_from = rng.bit_generator.state  # to tell why, should no vote come out
    votes, owner = _votes(instances, opt, rng)
    ids = [inst.instance_id for inst in instances]
    per_obj = dict(zip(ids, np.bincount(owner, minlength=len(ids)).tolist()))
    if votes.size == 0:
        return FocalEstimate(
            None, votes_per_object=per_obj, reason=_no_vote_reason(instances, opt, rng,
                                                                   drawn_from)
            + _lost_channel_hint(instances), **base
        )
    if opt.noise_bound.equal_widths:  # one width in log f: one sort of the centres
        st, back = stab_equal_width(np.log(votes), opt.noise_bound.log_half_width), np.exp
    else:
        lo, hi, back = opt.noise_bound.intervals(votes)
        st = interval_stabbing(lo, hi)
    inl = st.inliers
    count = int(inl.sum())
    ratio = count / votes.size
    interval = (float(back(st.region[0])), float(back(st.region[1])))
    inl_obj = dict(zip(ids, np.bincount(owner[inl], minlength=len(ids)).tolist()))
    est = FocalEstimate(
        None,
        inlier_count=count,
        inlier_ratio=ratio,
        interval=interval,
        votes_per_object=per_obj,
        inliers_per_object=inl_obj,
        votes=votes,
        **base,
    )
    if count < opt.min_frame_votes or ratio < opt.min_inlier_ratio:
        est.reason = (f"too little consensus: {count} agreeing votes ({ratio:.1%}) of "
                      f"{votes.size}" + _lost_channel_hint(instances))
        return est
    f0 = float(back(st.point))
    est.focal_votes = f0
    if not opt.refine:
        return _finish(est, f0, None, instances, opt, rng, poses)
    support = [calibrated_nocs(inst) for inst in instances]
    seed = int(rng.integers(2**32))
    fits = fit_objects(
        support,
        f0,
        max_pixels=opt.fit_pixels,
        depth_tilt=opt.depth_tilt,
        iterations=opt.fit_iterations,
        rng=np.random.default_rng(seed),
    )
    spread = np.array([_nocs_spread(i.p) for i in support])
    flat = [_flat_reason(r) for r in _flatness(instances, f0)]
    good = (
        fits.ok
        & (fits.quality >= opt.min_fit_quality)
        & np.isfinite(fits.var_log_focal)
        & (spread >= opt.min_nocs_spread)
        & np.array([why is None for why in flat])
    )
    for k, inst in enumerate(support):
        noisy = inst.sigma_p >= _NOISE_NOT_SHAPE
        if not fits.ok[k] or not np.isfinite(fits.var_log_focal[k]):
            est.rejected[inst.instance_id] = (
                "degenerate fit" + (f"; {_noise_reason(inst)}" if noisy else ""))
        elif spread[k] < opt.min_nocs_spread and noisy:
            # Denoising and the calibration keep of the NOCS what neighbouring pixels share.
            est.rejected[inst.instance_id] = (
                f"{_noise_reason(inst)}; their span {spread[k]:.3f} once denoised")
        elif spread[k] < opt.min_nocs_spread:
            est.rejected[inst.instance_id] = (
                f"its NOCS span {spread[k]:.3f} (< {opt.min_nocs_spread}): "
                "too small a piece of the category's shape"
            )
        elif fits.quality[k] < opt.min_fit_quality:
            est.rejected[inst.instance_id] = _quality_reason(fits.quality[k], opt.min_fit_quality)
        elif flat[k] is not None:
            est.rejected[inst.instance_id] = flat[k]
    first_flat = next(((inst.instance_id, why) for inst, why in zip(instances, flat)
                       if why is not None), None)
    if first_flat is None and not good.any():  # refused anyway: named alike if a channel is lost
        first_flat = next(iter(est.rejected.items()), None)
    # Across two or more objects, each in its own NOCS frame, a channel that does not vary is
    # a lost one even where no object reads flat (seen edge-on, an object's depth shows little
    # solid, and the frame answered from it at -85%).
    lost = _constant_channel(instances) if first_flat or len(instances) > 1 else None
    if lost is not None:
        # A channel constant over every object is a fault of the whole NOCS image: the objects
        # that are not solid in view are as wrong, only less visibly (frames with one channel
        # constant answered 19 of 30 at -34 to -91% before; refusing the flat objects alone
        # left 5). Any object that reads flat raises the question, also one refused for
        # another reason first (a user's 120 frames: 11 answered when only objects that passed
        # the other checks could, 2 now). One object's flat NOCS refuse only that object.
        shown = (f"object {first_flat[0]}: {first_flat[1]}" if first_flat
                 else f"its {len(instances)} objects all read it")
        est.reason = f"{_lost_text(lost)}: a lost channel? the frame is refused ({shown})"
        return est
    est.mirrored = [
        inst.instance_id for k, inst in enumerate(support) if good[k] and fits.mirrored[k]
    ]
    if not good.any():
        why = [f"{i}: {r}" for i, r in est.rejected.items()]
        more = f"; and {len(why) - 8} more (see rejected)" if len(why) > 8 else ""
        est.reason = ("no object whose NOCS explain its shape: " + "; ".join(why[:8]) + more
                      + _lost_channel_hint(instances))
        return est
    raw_spread = np.array([_nocs_spread(i.p) for i in instances])
    var, tau0 = _object_budgets(support, fits, good, spread, raw_spread, opt)
    logf = np.log(fits.focal)
    noise = np.minimum(fits.var_log_focal[good], var[good])  # as combine_objects clips it
    # The offsets of the intrinsics assumed (an assumed principal point's, a residual lens's
    # k1) that the objects' disagreement shows: their focal lengths corrected by them, the
    # uncertainty left into std_rel (.offsets).
    prior = np.append(pp_std, opt.lens_distortion_std)
    grads, cov = np.zeros((len(support), 3)), np.zeros((3, 3))
    estimated = bool(np.any(prior > 0))
    if estimated:
        grads[:, :2] = focal_gradients(support, f0, seed, pp_std, opt, logf)
        grads[:, 2] = lens_gradients(support, f0, seed, opt.lens_distortion_std, opt, logf)
        info, data = offset_information(logf[good], var[good] + tau0**2, grads[good])
        delta, cov = offset_posterior(info, data, prior)
        # For the window: the systematic budget repeats while these objects are in view; their
        # noise and the objects' prior spread (the window's frames show it vary) renew.
        repeating, _ = offset_information(logf[good], np.maximum(var[good] - noise, 1e-12),
                                          grads[good])
        logf = logf - grads @ delta
        if np.any(pp_std > 0):
            est.principal_point_offset = (float(delta[0]), float(delta[1]))
        if prior[2] > 0:
            est.lens_k1 = float(delta[2])
    comb = combine_objects(logf[good], var[good], fits.var_log_focal[good], tau0,
                           opt.object_tau_weight)
    if comb is None:
        est.reason = "no finite per-object estimate"
        return est
    kept = [inst for inst, g in zip(support, good) if g]
    var_offsets_obj = np.einsum("oi,ij,oj->o", grads, cov, grads)
    good_idx = np.flatnonzero(good)
    idx_used = good_idx[comb.used]
    w_noise = 1.0 / noise[comb.used]
    g_frame = (w_noise[:, None] * grads[idx_used]).sum(0) / w_noise.sum()
    var_offsets = float(g_frame @ cov @ g_frame)
    if estimated:
        est.intrinsics_evidence = IntrinsicsEvidence(
            prior, delta, cov, info, data, repeating, g_frame)
    for k, (inst, used) in enumerate(zip(kept, comb.used)):
        j = good_idx[k]
        if used:
            est.object_focals[inst.instance_id] = (
                float(np.exp(logf[j])),
                float(np.sqrt(var[j] + var_offsets_obj[j])),
                float(np.sqrt(fits.var_log_focal[j])),  # var[j] adds to it (.error_model)
            )
        else:
            est.rejected[inst.instance_id] = "its focal length disagrees with the other objects"
    # Poses only for objects whose own focal length is informative: a flat spurious blob or a
    # far, shallow object fits a similarity of almost any shape.
    used = [
        inst
        for inst, u in zip(kept, comb.used)
        if u and est.object_focals[inst.instance_id][1] <= opt.pose_max_std
    ]
    est.std_rel_noise = float(np.sqrt(comb.noise))
    est.std_rel_prior = float(np.sqrt(max(comb.prior, 0.0)))
    est.std_rel_principal_point = float(np.sqrt(g_frame[:2] @ cov[:2, :2] @ g_frame[:2]))
    est.std_rel_lens = float(abs(g_frame[2]) * np.sqrt(cov[2, 2]))
    combined = [inst for inst, u in zip(kept, comb.used) if u]
    return _finish(est, float(np.exp(comb.mean)), float(np.sqrt(comb.var + var_offsets)),
                   used, opt, rng, poses, combined)


def _object_budgets(support, fits, good, spread, raw_spread, opt: EstimatorOptions):
    """(each object's variance of log f, the prior spread between objects tau0) of the fitted
    objects ``good``."""
    # Errors that repeat in every frame show in no residual: their share of each object's
    # variance follows from the fit's lean on depth and on the NOCS (.error_model).
    relief_lean = depth_influence(support, fits, opt.fit_pixels, opt.depth_tilt)[:, 0]
    var = object_variances(support, fits, good, spread, raw_spread, relief_lean, opt)
    # The objects' prior spread stands for the depth network's errors of each object's relief,
    # which move f by the fits' lean on depth: about one for one with noisy NOCS, almost nothing
    # when exact NOCS let the pixels fix f.
    lean = relief_lean[good & np.isfinite(relief_lean)]
    tau0 = opt.object_tau * (float(np.sqrt(np.mean(lean**2))) if lean.size else 1.0)
    return var, tau0


def _principal_point_std(given, std, opt: EstimatorOptions, w: int, h: int) -> np.ndarray:
    """(sx, sy) pixels: ``std`` where the caller says it, else none for a given principal point
    and ``opt.principal_point_std`` of the image's width and height for the assumed centre."""
    if std is None:
        std = (0.0, 0.0) if given is not None else (opt.principal_point_std * w,
                                                    opt.principal_point_std * h)
    out = np.asarray(std, dtype=np.float64).reshape(-1)
    if out.shape != (2,) or not np.all(np.isfinite(out)) or np.any(out < 0):
        raise ValueError(f"principal_point_std must be two finite pixels >= 0, got {std!r}")
    return out


def _finish(
    est: FocalEstimate,
    focal: float,
    std_rel,
    instances,
    opt: EstimatorOptions,
    rng,
    poses: bool = False,
    measured=None,
) -> FocalEstimate:
    """Enforce the focal range, then attach the extents of the objects that made the estimate
    (``measured``, default ``instances``) and the poses of ``instances``."""
    lo, hi = opt.focal_range
    if not lo <= focal <= hi:
        est.reason = f"focal {focal:.1f} px outside focal_range [{lo:g}, {hi:g}]"
        return est
    est.focal, est.std_rel, est.instances = focal, std_rel, list(instances)
    sizes = {
        inst.instance_id: _image_scale_depth(inst)
        for inst in (instances if measured is None else measured)
    }
    est.object_extents = {i: r * d for i, (r, d) in sizes.items()}
    est.object_radii = {i: r for i, (r, _) in sizes.items()}
    if poses:
        est.objects = estimate_poses(est.instances, focal, exclude=est.mirrored, rng=rng)
    return est
