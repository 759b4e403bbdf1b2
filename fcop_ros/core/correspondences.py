"""Per-instance correspondences (x, d, p) from depth, NOCS and instance-mask images.

Conventions and choices:
- ``depth``: (H,W) z-depth in metres; NaN, inf and values <= 0 are invalid.
- ``nocs``: (H,W,3) in [0,1]; an all-zero pixel means "no prediction"; non-finite or far
  outside [0,1] (beyond ``nocs_tolerance``) is invalid.
- ``mask``: (H,W) integer; 0 (and negatives) is background, every other value one instance.
- Image points x are pixel centres on integer coordinates, relative to the principal point,
  which defaults to ((W-1)/2, (H-1)/2).
- Edge pixels: each instance mask is eroded by ``erode_px`` pixels first, because learned
  depth and NOCS bleed across object boundaries.
- Tiny instances: fewer than ``min_object_pixels`` usable pixels after erosion are skipped.
- Noisy pixels: a pixel whose depth or NOCS differs from the robust local mean of its own
  instance by more than ``outlier_sigma`` robust sigmas is dropped; so is a pixel whose smoothed
  depth gradient exceeds ``edge_sigma`` robust sigmas of the instance's gradients (depth that
  bleeds across a boundary forms a steep ramp). With ``denoise_radius`` > 0 depth and NOCS are
  replaced by their local mean over the instance's valid pixels in a (2r+1)^2 window, and so are
  the image points (through the camera points d u, d v), so that every averaged triple stays a
  correspondence of the model. Noise is
  estimated from second differences (blind to planar slopes); below ``noise_floor`` (relative
  to depth; 4x that in NOCS units) it is surface curvature, and the data are left as they are.
- Large instances are randomly subsampled to ``max_pixels`` to bound the cost.

Where the compiled kernels are on (:mod:`fcop_ros.core.compiled`) each instance's crop is
processed by one of them (``_crop_kernel``) instead of the numpy steps on a mosaic of all crops
(``_extract_mosaic``), which stay as the fallback: both keep the same pixels and draw the same
random subsets, and their values agree up to rounding.
"""
from __future__ import annotations

import math
import sys
from dataclasses import dataclass, replace

import cv2
import numpy as np
from scipy import ndimage

from . import compiled
from .camera import image_centre
from .compiled import kernel, kernel_helper
from .robust import MAD_TO_SIGMA


@dataclass
class Instance:
    """Correspondences of one instance.

    instance_id: mask value; x (n,2) px relative to the principal point; d (n,) metres; p (n,3)
    NOCS in [0,1]; var_d (n,) and var_p (n,) estimated noise variances of d (m^2) and of each
    NOCS coordinate after denoising; sigma_d and
    sigma_p: estimated per-pixel noise of the raw depth (m) and NOCS; mask_pixels: pixels of
    the instance in the mask; valid_pixels: usable pixels before subsampling; at_border: its
    mask reaches the edge of the image, which cuts it.
    """

    instance_id: int
    x: np.ndarray
    d: np.ndarray
    p: np.ndarray
    var_d: np.ndarray
    sigma_d: float
    sigma_p: float
    mask_pixels: int
    valid_pixels: int
    var_p: np.ndarray | None = None
    at_border: bool = False


class InstanceList(list):
    """The instances of a frame; ``skipped`` counts those left out by ``max_instances``."""

    skipped = 0


def check_images(depth, nocs, mask):
    """Validate shapes and types; return float64 depth, float64 nocs and integer mask.

    Raises ValueError with a message naming the offending input."""
    depth = np.asarray(depth)
    nocs = np.asarray(nocs)
    mask = np.asarray(mask)
    if depth.ndim != 2:
        raise ValueError(f"depth must be an (H,W) image, got shape {depth.shape}")
    if nocs.ndim != 3 or nocs.shape[2] != 3:
        raise ValueError(f"nocs must be an (H,W,3) image, got shape {nocs.shape}")
    if mask.ndim != 2:
        raise ValueError(f"mask must be an (H,W) image, got shape {mask.shape}")
    if not (depth.shape == nocs.shape[:2] == mask.shape):
        raise ValueError(f"image sizes differ: depth {depth.shape}, nocs {nocs.shape[:2]}, "
                         f"mask {mask.shape}")
    if not _numeric(depth.dtype):
        raise ValueError(f"depth must be numeric, got dtype {depth.dtype}")
    if depth.dtype.kind in "iu":
        raise ValueError(
            f"depth has integer dtype {depth.dtype}: metres are expected, as floats. A 16UC1 "
            "depth image is millimetres (REP-118): pass depth / 1000.0 (msg_adapters converts "
            "ROS images)"
        )
    if not _numeric(nocs.dtype):
        raise ValueError(f"nocs must be numeric, got dtype {nocs.dtype}")
    if mask.dtype == bool:
        mask = mask.astype(np.int32)
    if not (mask.dtype.kind in "iu" or np.issubdtype(mask.dtype, np.integer)):
        raise ValueError(f"mask must hold integer instance ids, got dtype {mask.dtype}")
    if mask.dtype.kind == "u" and mask.dtype.itemsize == 8 and mask.size and (
            int(mask.max()) > np.iinfo(np.int64).max):
        raise ValueError("mask ids above 2**63 - 1 are not supported (as 64-bit signed "
                         "integers they read as negative: background)")
    return depth, nocs, mask


NOCS_TOLERANCE = 0.05  # NOCS this far outside [0, 1] still count as in range


def nocs_range(nocs, mask, stride: int = 8):
    """(share, sampled, low, high) of the object pixels on every ``stride``-th row and column
    that carry a prediction (finite, not all zero): the share whose NOCS lie outside [0, 1]
    beyond NOCS_TOLERANCE, their number, and the smallest and largest value among them. A few
    microseconds on 640x480, so every frame is checked: pixels out of range are dropped one by
    one, and NOCS in another convention (centred, 8-bit) would otherwise leave a biased rest."""
    sub = mask[::stride, ::stride]
    at = np.flatnonzero(sub > 0)
    rows, cols = at // sub.shape[1] * stride, at % sub.shape[1] * stride
    if nocs.flags.c_contiguous:
        on = np.take(nocs.reshape(-1, 3), rows * nocs.shape[1] + cols, axis=0)
    else:
        on = nocs[rows, cols]
    # Per pixel, numpy's min and max over an axis of three cost 20 times these.
    lo = np.minimum(np.minimum(on[:, 0], on[:, 1]), on[:, 2])
    hi = np.maximum(np.maximum(on[:, 0], on[:, 1]), on[:, 2])
    keep = np.isfinite(lo) & np.isfinite(hi) & ((lo != 0) | (hi != 0))
    lo, hi = lo[keep], hi[keep]
    if not len(lo):
        return 0.0, 0, 0.0, 0.0
    out = (lo < -NOCS_TOLERANCE) | (hi > 1 + NOCS_TOLERANCE)
    return float(np.count_nonzero(out)) / len(lo), len(lo), float(lo.min()), float(hi.max())


def nocs_range_hint(low: float, high: float, dtype=None) -> str:
    """What NOCS values spanning [low, high] suggest, for a reason: integers of ``dtype`` (the
    image's type) or floats up to 255 to be divided by their type's top, centred, or other."""
    integer = dtype is not None and np.dtype(dtype).kind in "iu"
    if high > 1.5 and (integer or high <= 255 * (1 + NOCS_TOLERANCE)):
        bits, top = (np.dtype(dtype).itemsize * 8, np.iinfo(dtype).max) if integer else (8, 255)
        return (f"NOCS values reach {high:.4g}; they must lie in [0, 1]: divide {bits}-bit NOCS "
                f"by {top}")
    if low < -NOCS_TOLERANCE and high <= 0.5 + NOCS_TOLERANCE:
        return (f"NOCS values span [{low:.3g}, {high:.3g}]; they must lie in [0, 1]: centred "
                "NOCS (in [-0.5, 0.5])? add 0.5")
    return f"NOCS values span [{low:.3g}, {high:.3g}]; they must lie in [0, 1]"


def _numeric(dtype) -> bool:
    """A floating or integer dtype; the common kinds by their letter (np.issubdtype costs a few
    microseconds per call, and every frame checks three images twice)."""
    return (dtype.kind in "fiu" or np.issubdtype(dtype, np.floating)
            or np.issubdtype(dtype, np.integer))


def instance_ids(mask: np.ndarray, min_pixels: int = 1):
    """Positive instance ids with at least ``min_pixels`` pixels, and their pixel counts
    (negative values, like 0, are background)."""
    flat = mask.ravel()
    top = int(flat.max()) if flat.size else 0
    if top <= 0:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    if top <= 1 << 20:
        counts = np.bincount(flat if flat.dtype.kind == "u" else np.maximum(flat, 0),
                             minlength=top + 1)
        ids = np.flatnonzero(counts)
        ids = ids[ids > 0]
        counts = counts[ids]
    else:
        ids, counts = np.unique(flat[flat > 0], return_counts=True)
    keep = counts >= max(min_pixels, 1)
    return ids[keep].astype(np.int64), counts[keep].astype(np.int64)


def _bounding_boxes(labels: np.ndarray, ids: np.ndarray):
    """(row0, row1, col0, col1) half-open bounding box of each id, in one pass over the image;
    ``labels`` holds no negative values."""
    if ids.max() <= 1 << 16:
        objs = ndimage.find_objects(labels, max_label=int(ids.max()))
        return [(objs[i - 1][0].start, objs[i - 1][0].stop, objs[i - 1][1].start,
                 objs[i - 1][1].stop) for i in ids]
    boxes = []
    for iid in ids:
        r = np.flatnonzero((labels == iid).any(1))
        c = np.flatnonzero((labels == iid).any(0))
        boxes.append((r[0], r[-1] + 1, c[0], c[-1] + 1))
    return boxes


_FEW_IDS = 16  # masks whose largest id is at most this take the per-id path


def _few_ids_and_boxes(mask: np.ndarray, top_id: int, min_pixels: int):
    """instance_ids and _bounding_boxes for a mask whose ids are at most ``top_id``: one
    comparison per possible id, counted and boxed."""
    ids, counts, boxes = [], [], []
    for iid in range(1, top_id + 1):
        eq = mask == iid
        n = np.count_nonzero(eq)
        if n >= max(min_pixels, 1):
            c, r, bw, bh = cv2.boundingRect(eq.view(np.uint8))
            ids.append(iid)
            counts.append(n)
            boxes.append((r, r + bh, c, c + bw))
    return np.array(ids, dtype=np.int64), np.array(counts, dtype=np.int64), boxes


def _mask_bytes(mask: np.ndarray) -> np.ndarray:
    """The mask's native integers as rows of bytes (h, w * itemsize), of a C-contiguous copy
    only if it is not one already: what the kernels read, one compiled signature for every
    integer type."""
    mask = np.ascontiguousarray(mask)
    return mask.view(np.uint8).reshape(mask.shape[0], mask.shape[1] * mask.dtype.itemsize)


def _few_ids_and_boxes_compiled(raw: np.ndarray, dtype, top_id: int, min_pixels: int):
    """_few_ids_and_boxes by one compiled pass over the mask's bytes ``raw`` (``_mask_bytes``
    of a mask of integer ``dtype``), so the one signature warm_up compiles serves every integer
    type. None as soon as the pass meets an id above ``top_id`` (so no np.max pass is needed
    first)."""
    count, box, above = _few_ids_k(raw, dtype.itemsize, top_id, dtype.kind == "i")
    if above:
        return None
    ids = np.flatnonzero(count >= max(min_pixels, 1))
    ids = ids[ids > 0]
    return ids.astype(np.int64), count[ids], [tuple(int(v) for v in box[i]) for i in ids]


def _second_diff_sigma(img: np.ndarray, ok: np.ndarray) -> float:
    """Robust per-pixel noise sigma from horizontal and vertical second differences."""
    vals = []
    for a, okv in ((img[::3], ok[::3]), (img[:, ::3].T, ok[:, ::3].T)):
        dd = a[:, :-2] - 2 * a[:, 1:-1] + a[:, 2:]
        m = okv[:, :-2] & okv[:, 1:-1] & okv[:, 2:]
        vals.append(dd[m].ravel())
    v = np.concatenate(vals)
    if v.size < 8:
        return 0.0
    v = _thin(v)
    return MAD_TO_SIGMA * _median(np.abs(v - _median(v))) / np.sqrt(6.0)


def _median(v: np.ndarray) -> float:
    """np.median of a 1-D array without its generic overhead (the same value)."""
    m = v.size
    k = m // 2
    if m % 2:
        return float(np.partition(v, k)[k])
    part = np.partition(v, (k - 1, k))
    return 0.5 * float(part[k - 1] + part[k])


def _mean(v) -> float:
    """float(np.mean(v)); for a non-empty 1-D float64 array without np.mean's generic overhead
    (the same value: numpy's pairwise sum divided by the count)."""
    if isinstance(v, np.ndarray) and v.dtype == np.float64 and v.ndim == 1 and v.size:
        return float(np.add.reduce(v)) / v.size
    return float(np.mean(v))


def _thin(v: np.ndarray, n: int = 600) -> np.ndarray:
    """A strided subset of about n values: robust scales need no more, and medians are costly."""
    return v[:: v.size // n] if v.size > 2 * n else v


def _gradient(img: np.ndarray, ok: np.ndarray) -> np.ndarray:
    """Largest absolute central difference along rows or columns where both neighbours are valid
    (0 elsewhere)."""
    g = np.zeros_like(img)
    both = ok[:, :-2] & ok[:, 2:]
    g[:, 1:-1] = np.where(both, np.abs(img[:, 2:] - img[:, :-2]) * 0.5, 0.0)
    both = ok[:-2] & ok[2:]
    g[1:-1] = np.maximum(g[1:-1], np.where(both, np.abs(img[2:] - img[:-2]) * 0.5, 0.0))
    return g


def _local_means(w: np.ndarray, radius: int, vals: np.ndarray):
    """Mean of each plane of ``vals`` (C,H,W) over the pixels with w=1 in a (2r+1)^2 box, and
    the count: (means (C,H,W), count (H,W)).

    One single-channel box filter of the weight and the weighted planes stacked one above the
    other, each followed by r rows of zeros, so that no box reaches into the next plane: the
    same sums as a filter of each plane of its own, in one OpenCV call and a few whole-stack
    numpy operations on contiguous rows. Products are formed in float64 and rounded to float32,
    quotients are float32, widened to float64."""
    c, h, wd = vals.shape
    k = (2 * radius + 1, 2 * radius + 1)
    buf = np.zeros((c + 1, h + radius, wd), np.float32)
    buf[0, :h] = w
    np.multiply(vals, buf[0, :h], out=buf[1:, :h])
    sums = cv2.boxFilter(buf.reshape(-1, wd), -1, k, normalize=False,
                         borderType=cv2.BORDER_CONSTANT).reshape(buf.shape)[:, :h]
    cnt = np.maximum(sums[0], 1e-6)
    return np.divide(sums[1:], cnt, out=np.empty(vals.shape)), sums[0].astype(np.float64)


def _band_means(w: np.ndarray, bands, vals: np.ndarray):
    """_local_means over row bands [(radius, start, stop), ...] of a mosaic, each with its own
    radius (the bands hold whole crops and their zero rows, so no box crosses a band)."""
    if len(bands) == 1:
        return _local_means(w, bands[0][0], vals)
    means, cnt = np.empty(vals.shape), np.empty(w.shape)
    for rad, y0, y1 in bands:
        means[:, y0:y1], cnt[y0:y1] = _local_means(w[y0:y1], rad, vals[:, y0:y1])
    return means, cnt


def extract_instances(depth, nocs, mask, principal_point=None, *, min_object_pixels: int = 50,
                      erode_px: int = 1, denoise_radius: int = 2, outlier_sigma: float = 4.0,
                      max_pixels: int = 2000, nocs_tolerance: float = NOCS_TOLERANCE,
                      noise_floor: float = 5e-4,
                      edge_sigma: float = 0.0, max_instances: int | None = None,
                      rng: np.random.Generator | None = None):
    """Build the per-instance correspondences of one frame (see the module docstring).

    Returns a list of :class:`Instance`, sorted by instance id. Shape or type errors raise
    ValueError; instances without enough usable pixels are simply absent. With
    ``max_instances`` only the largest that many are processed (the cost stays linear in the
    pixels however many instances a mask holds); the list's ``skipped`` attribute counts the rest.
    """
    depth, nocs, mask = check_images(depth, nocs, mask)
    h, w = depth.shape
    if principal_point is None:
        cx, cy = image_centre(w, h)
    else:
        cx, cy = (float(v) for v in principal_point)
    rng = np.random.default_rng() if rng is None else rng
    # The kernels read the mask's bytes as native little-endian integers.
    compiled_mask = compiled.ENABLED and mask.dtype.isnative and sys.byteorder == "little"
    raw = _mask_bytes(mask) if compiled_mask else None
    few = None
    if raw is not None and mask.size:
        # One compiled pass counts and boxes the ids up to _FEW_IDS, or stops at a larger id.
        few = _few_ids_and_boxes_compiled(raw, mask.dtype, _FEW_IDS, min_object_pixels)
    top_id = int(mask.max()) if few is None and mask.size else 0
    if few is not None:
        ids, counts, boxes = few
    elif top_id <= _FEW_IDS:
        # Few possible ids: one comparison per id gives its count and box (OpenCV), about 3x
        # faster than a histogram of the whole image plus a box pass.
        ids, counts, boxes = _few_ids_and_boxes(mask, top_id, min_object_pixels)
    else:
        # Negative ids are background; the clipped ids viewed as unsigned need no second clip.
        labels = mask if mask.dtype.kind == "u" else np.maximum(mask, 0).view(
            np.dtype(f"u{mask.dtype.itemsize}"))
        ids, counts = instance_ids(labels, min_object_pixels)
        boxes = None
    out = InstanceList()
    if ids.size == 0:
        return out
    if max_instances is not None and ids.size > max_instances:
        top = np.sort(np.argsort(-counts, kind="stable")[:max_instances])
        out.skipped = int(ids.size - top.size)
        ids, counts = ids[top], counts[top]
        boxes = None if boxes is None else [boxes[k] for k in top]
    if boxes is None:
        boxes = _bounding_boxes(labels, ids)
    pad = denoise_radius + erode_px + 1
    crops = []
    for iid, npix, (r0, r1, c0, c1) in zip(ids, counts, boxes):
        at_border = bool(r0 <= 0 or c0 <= 0 or r1 >= h or c1 >= w)
        r0, r1, c0, c1 = max(r0 - pad, 0), min(r1 + pad, h), max(c0 - pad, 0), min(c1 + pad, w)
        # Large instances are processed on a strided grid: far more pixels than max_pixels add
        # cost but little accuracy.
        st = max(1, math.ceil(math.sqrt(float(npix) / (2.0 * max_pixels))))
        if raw is not None:
            inst = _eroded_crop_k(raw, mask.dtype.itemsize, int(iid), r0, r1, c0, c1,
                                  int(erode_px), st)
        else:
            inst = mask[r0:r1, c0:c1] == iid
            if erode_px > 0:
                inst = cv2.erode(inst.astype(np.uint8), np.ones((3, 3), np.uint8),
                                 iterations=int(erode_px),
                                 borderType=cv2.BORDER_CONSTANT, borderValue=0).astype(bool)
            inst = inst[::st, ::st]
        crops.append(_Crop(int(iid), int(npix), r0, c0, st, inst,
                           depth[r0:r1:st, c0:c1:st], nocs[r0:r1:st, c0:c1:st], at_border))
    if not crops:
        return out
    # The radius of each crop's box filter: the same window in image pixels (it follows the
    # stride).
    rads = [max(int(round(denoise_radius / cr.st)), 1) for cr in crops]
    if compiled.ENABLED:
        _emit_compiled(out, crops, rads, depth, nocs, (cx, cy), rng, min_object_pixels,
                       denoise_radius, outlier_sigma, max_pixels, nocs_tolerance, noise_floor,
                       edge_sigma)
        return out
    # All instances are processed together, their crops stacked in one mosaic, ordered by
    # their radius.
    order = sorted(range(len(crops)), key=rads.__getitem__)
    found = _extract_mosaic([crops[k] for k in order], order, [rads[k] for k in order], (cx, cy),
                            min_object_pixels, denoise_radius, outlier_sigma, nocs_tolerance,
                            noise_floor, edge_sigma)
    for k in sorted(found):  # in instance-id order: the random subsets draw as before
        cr = crops[k]
        res = found[k]
        rr, cc = res.rr, res.cc
        valid = rr.size
        if valid > max_pixels:
            pick = rng.choice(valid, size=max_pixels, replace=False)
            rr, cc = rr[pick], cc[pick]
        y0 = res.y0
        if res.x_img is None:
            x = np.column_stack([cc * cr.st + cr.c0 - cx,
                                 (rr - y0) * cr.st + cr.r0 - cy]).astype(np.float64)
            var_d = np.full(rr.size, res.sigma_d ** 2)
            var_p = np.full(rr.size, res.sigma_p ** 2)
        else:
            x = np.column_stack([res.x_img[0][rr, cc], res.x_img[1][rr, cc]])
            var_d = res.sigma_d ** 2 / np.maximum(res.cnt[rr, cc], 1.0)
            var_p = res.sigma_p ** 2 / np.maximum(res.cnt[rr, cc], 1.0)
        out.append(Instance(cr.iid, x, res.dz[rr, cc].astype(np.float64, copy=False),
                            np.ascontiguousarray(res.pz[:, rr, cc].T), var_d, res.sigma_d,
                            res.sigma_p, cr.npix, int(valid), var_p, cr.at_border))
    return out


def _kernel_images(depth, nocs):
    """depth and NOCS as _crop_kernel reads them: both float32 (the node's images) as they
    are, else both float64. The kernel widens each value it reads, exactly, so both give the
    same bits; converting a whole float32 frame to float64 first cost more than a millisecond
    (640x480). Two types only, both compiled by warm_up, so no frame waits for a compilation."""
    if depth.dtype == np.float32 and nocs.dtype == np.float32:
        return np.ascontiguousarray(depth), np.ascontiguousarray(nocs)
    return (np.ascontiguousarray(depth, dtype=np.float64),
            np.ascontiguousarray(nocs, dtype=np.float64))


def _emit_compiled(out, crops, rads, depth, nocs, centre, rng, min_object_pixels,
                   denoise_radius, outlier_sigma, max_pixels, nocs_tolerance, noise_floor,
                   edge_sigma):
    """The crops' instances appended to ``out`` by the compiled kernel, one call per crop: the
    same instances, pixels and random subsets as _extract_mosaic and the loop that reads it."""
    cx, cy = centre
    depth, nocs = _kernel_images(depth, nocs)
    args = (int(max(min_object_pixels, 3)), int(denoise_radius), float(outlier_sigma),
            float(nocs_tolerance), float(noise_floor), float(edge_sigma))
    for cr, rad in zip(crops, rads):
        status, rr, cc, d, p, xu, xv, cn, sd, sp = _crop_kernel(
            depth, nocs, np.ascontiguousarray(cr.inst), cr.r0, cr.c0, cr.st, rad, float(cx),
            float(cy), *args)
        if status == 0:
            continue
        valid = rr.size
        if status == 2:  # denoised: the kept pixels' values gathered and their noise in one pass
            pick = (rng.choice(valid, size=max_pixels, replace=False) if valid > max_pixels
                    else np.arange(valid))
            x, d, p, var_d, var_p = _denoised_pick_k(pick, d, p, xu, xv, cn, float(sd ** 2),
                                                     float(sp ** 2))
            out.append(Instance(cr.iid, x, d, p, var_d, sd, sp, cr.npix, int(valid), var_p,
                                cr.at_border))
            continue
        if valid > max_pixels:
            pick = rng.choice(valid, size=max_pixels, replace=False)
            # np.take gathers the rows of p several times faster than p[pick].
            rr, cc, d, p = rr[pick], cc[pick], d[pick], np.take(p, pick, axis=0)
        # Raw values (status 1): the image points are the pixel centres.
        x = np.column_stack([cc * cr.st + cr.c0 - cx,
                             rr * cr.st + cr.r0 - cy]).astype(np.float64)
        var_d = np.full(rr.size, sd ** 2)
        var_p = np.full(rr.size, sp ** 2)
        out.append(Instance(cr.iid, x, d, p, var_d, sd, sp, cr.npix, int(valid), var_p,
                            cr.at_border))


@dataclass
class _Crop:
    """One instance's strided crop: id, mask pixels, top-left corner, stride, eroded mask and
    the depth and NOCS views."""

    iid: int
    npix: int
    r0: int
    c0: int
    st: int
    inst: np.ndarray
    dc: np.ndarray
    pc: np.ndarray
    at_border: bool = False


@dataclass
class _Found:
    """An instance's usable pixels (rr, cc) in its mosaic (rows from y0), where to read them,
    and its noise levels."""

    rr: np.ndarray
    cc: np.ndarray
    y0: int
    dz: np.ndarray
    pz: np.ndarray
    x_img: tuple | None
    cnt: np.ndarray | None
    sigma_d: float
    sigma_p: float


def _segments(sel: np.ndarray, y0s: np.ndarray):
    """Offsets of each crop's entries in ``values[sel]`` (row-major: each crop's are
    contiguous, the crops being stacked vertically from rows y0s)."""
    counts = np.add.reduceat(np.count_nonzero(sel, axis=1), y0s)
    return np.concatenate([[0], np.cumsum(counts)]), counts


def _extract_mosaic(crops, keys, rads, centre, min_object_pixels, denoise_radius,
                    outlier_sigma, nocs_tolerance, noise_floor, edge_sigma):
    """The per-instance steps of extract_instances on one mosaic of the crops stacked
    vertically (in ascending order of their box radius ``rads``, each followed by at least its
    radius in zero rows, so that no box and no difference reaches another crop): every
    whole-image step is one numpy call for all of them (one OpenCV box filter per radius), and
    the per-instance statistics (medians) are read from contiguous segments. Gives
    {key: _Found} of the instances with enough usable pixels."""
    cx, cy = centre
    min_px = max(min_object_pixels, 3)
    y0s, y, bands = [], 0, []
    for cr, rad in zip(crops, rads):
        if not bands or bands[-1][0] != rad:
            bands.append([rad, y, y])
        y0s.append(y)
        y += cr.inst.shape[0] + rad
        bands[-1][2] = y
    hm, wm = y, max(cr.inst.shape[1] for cr in crops)
    y0s = np.array(y0s)
    inst = np.zeros((hm, wm), bool)
    dc = np.zeros((hm, wm))
    pc = np.zeros((3, hm, wm))
    row_of = np.zeros(hm, np.intp)  # the crop of each mosaic row
    uu = np.zeros((hm, wm))
    vv = np.zeros((hm, 1))
    for k, (cr, y0) in enumerate(zip(crops, y0s)):
        hk, wk = cr.inst.shape
        inst[y0:y0 + hk, :wk] = cr.inst
        dc[y0:y0 + hk, :wk] = cr.dc
        pc[:, y0:y0 + hk, :wk] = cr.pc.transpose(2, 0, 1)
        row_of[y0:] = k
        uu[y0:y0 + hk, :wk] = (np.arange(wk) * cr.st + cr.c0) - cx
        vv[y0:y0 + hk, 0] = (np.arange(hk) * cr.st + cr.r0) - cy
    # Channel by channel: numpy reductions over a length-3 axis are slow.
    with np.errstate(invalid="ignore"):
        ok = inst & (dc > 0) & (dc < np.inf)
        nonzero = np.zeros_like(ok)
        for ch in range(3):
            v = pc[ch]
            ok &= (v >= -nocs_tolerance) & (v <= 1 + nocs_tolerance)  # false for NaN
            nonzero |= v != 0
        ok &= nonzero
    n_ok = np.add.reduceat(np.count_nonzero(ok, axis=1), y0s)
    alive = n_ok >= min_px
    if not alive.any():
        return {}
    if not alive.all():
        ok &= alive[row_of][:, None]
    # Planes of depth, NOCS and (later) the camera-plane points d u, d v, zero off the valid
    # pixels: every local mean below is one box filter of a stack of them.
    V = np.zeros((6, hm, wm))
    np.copyto(V[0], dc, where=ok)  # not a product: invalid depth may be NaN or inf
    np.copyto(V[1:4], pc, where=ok)
    dz, pz = V[0], V[1:4]
    off, _ = _segments(ok, y0s)
    dvals = dz[ok]
    sig_d, sig_p, depth_med = np.zeros(len(crops)), np.zeros(len(crops)), np.zeros(len(crops))
    for k, (cr, y0) in enumerate(zip(crops, y0s)):
        if not alive[k]:
            continue
        hk, wk = cr.inst.shape
        okk = ok[y0:y0 + hk, :wk]
        sd = _second_diff_sigma(dz[y0:y0 + hk, :wk], okk)
        # NOCS noise, the RMS over the channels: the same for a mirrored or permuted NOCS.
        sp = float(np.sqrt(np.mean([_second_diff_sigma(pz[c, y0:y0 + hk, :wk], okk) ** 2
                                    for c in range(3)])))
        # Below the floor the "noise" is surface curvature: treat the data as exact (no
        # smoothing, whose curvature bias would then dominate, and no bias correction).
        depth_med[k] = float(_median(_thin(dvals[off[k]:off[k + 1]])))
        if sd < noise_floor * depth_med[k]:
            sd = 0.0
        # NOCS curvature is larger: an object spans ~200 px of ~1 NOCS unit.
        if sp < 4 * noise_floor:
            sp = 0.0
        sig_d[k], sig_p[k] = sd, sp
    md = mp = cnt = x_img = None
    means_of = np.ones(len(crops), bool)  # per crop: md, mp, cnt are means over its ok pixels
    denoise = np.zeros(len(crops), bool)
    if denoise_radius > 0 or outlier_sigma > 0:
        means, cnt = _band_means(ok, bands, V[:4])
        md, mp = means[0], means[1:4]
        if outlier_sigma > 0:
            rd = np.abs(dz - md)
            dp = pz - mp
            rp = np.sqrt(dp[0] ** 2 + dp[1] ** 2 + dp[2] ** 2)
            rdv, rpv = rd[ok], rp[ok]
            thr_d, thr_p = np.full(len(crops), np.inf), np.full(len(crops), np.inf)
            for k in np.flatnonzero(alive):
                s = slice(off[k], off[k + 1])
                thr_d[k] = outlier_sigma * max(MAD_TO_SIGMA * _median(_thin(rdv[s])),
                                               1e-9 * depth_med[k])
                thr_p[k] = outlier_sigma * max(MAD_TO_SIGMA * _median(_thin(rpv[s])), 1e-9)
            ok2 = ok & (rd <= thr_d[row_of][:, None]) & (rp <= thr_p[row_of][:, None])
            n2 = np.add.reduceat(np.count_nonzero(ok2, axis=1), y0s)
            take = alive & (n2 >= min_px) & (n2 != n_ok)  # ok2 is a subset: equal iff as many
            if take.any():
                ok = np.where(take[row_of][:, None], ok2, ok)
                means, cnt = _band_means(ok, bands, V[:4])
                md, mp = means[0], means[1:4]
        if edge_sigma > 0:
            # Depth bleeding across object boundaries makes steep ramps: drop pixels whose
            # (smoothed) depth gradient is far above the instance's typical gradient.
            g = _gradient(md, ok)
            sel = ok & (g > 0)
            goff, gcount = _segments(sel, y0s)
            gvals = g[sel]
            thr_g = np.full(len(crops), np.inf)
            has = alive & (gcount >= 8)
            for k in np.flatnonzero(has):
                thr_g[k] = (edge_sigma * MAD_TO_SIGMA * _median(_thin(gvals[goff[k]:goff[k + 1]]))
                            + noise_floor * depth_med[k])
            if has.any():
                ok2 = ok & (g <= thr_g[row_of][:, None])
                n2 = np.add.reduceat(np.count_nonzero(ok2, axis=1), y0s)
                take = has & (n2 >= min_px)
                if take.any():
                    ok = np.where(take[row_of][:, None], ok2, ok)
                    means_of &= ~take
        denoise = alive & (denoise_radius > 0) & ((sig_d > 0) | (sig_p > 0))
        if denoise.any():
            # Average whole correspondences, not one channel: the model is affine in the
            # camera point (d u, d v, d) and in the NOCS, so means over the same pixels stay
            # on it, even at the border, where the window is one-sided and smoothing NOCS
            # alone shrinks the object (a focal bias of several percent on small objects).
            np.multiply(dz, uu, out=V[4])
            np.multiply(dz, vv, out=V[5])
            # Means over every crop's final pixels (for crops whose pixels did not change since
            # the last means, the same values).
            means, cnt = _band_means(ok, bands, V)
            md, mp = means[0], means[1:4]
            with np.errstate(divide="ignore", invalid="ignore"):
                x_img = (means[4] / md, means[5] / md)
    rr_all, cc_all = np.nonzero(ok)
    roff, _ = _segments(ok, y0s)
    found = {}
    for k, (key, y0) in enumerate(zip(keys, y0s)):
        if not alive[k]:
            continue
        s = slice(roff[k], roff[k + 1])
        if s.stop - s.start < min_px:
            continue
        if denoise[k]:
            found[key] = _Found(rr_all[s], cc_all[s], int(y0), md, mp, x_img, cnt,
                                float(sig_d[k]), float(sig_p[k]))
        else:
            found[key] = _Found(rr_all[s], cc_all[s], int(y0), dz, pz, None, None,
                                float(sig_d[k]), float(sig_p[k]))
    return found


def calibrated_nocs(inst: Instance) -> Instance:
    """The instance with its NOCS replaced by their expectation given the noise left after
    denoising (regression calibration): noise in the NOCS, the fit's regressor, would otherwise
    shrink the fitted similarity along the object's thin axes, like a shape error."""
    if inst.var_p is None or len(inst.p) < 4:
        return inst
    noise = _mean(inst.var_p)
    if not noise > 0:
        return inst
    if compiled.ENABLED:
        p = _calibrated_nocs_k(np.ascontiguousarray(inst.p, np.float64), noise)
        if type(inst) is Instance:  # dataclasses.replace, without its generic field walk
            return Instance(inst.instance_id, inst.x, inst.d, p, inst.var_d, inst.sigma_d,
                            inst.sigma_p, inst.mask_pixels, inst.valid_pixels, inst.var_p,
                            inst.at_border)
        return replace(inst, p=p)
    centre = inst.p.mean(0)
    q = inst.p - centre
    cov = q.T @ q / len(q)
    val, vec = np.linalg.eigh(cov)
    gain = np.clip(val - noise, 0.0, None) / np.maximum(val, 1e-300)
    p = centre + ((q @ vec) * gain) @ vec.T
    return replace(inst, p=p)


# Compiled kernels (fcop_ros.core.compiled): each instance's crop in one pass of plain loops,
# giving what _extract_mosaic gives for it, selections bit for bit (box sums are formed exactly
# in float64 and rounded to float32, as OpenCV's box filter does; medians are np.median's).

@kernel_helper
def _select_k(v, lo, hi, k):
    """Reorder v[lo:hi+1] so that v[k] holds its value of that rank, with no larger value
    before it and no smaller one after it (quickselect). Each pass moves the values below the
    pivot (the median of three), then those equal to it, to the front by unconditional swaps
    (branch-free Lomuto partitions): on fresh data about 3x faster than Hoare's branching
    scans, whose comparisons the processor mispredicts half the time (0.45 / 1.15 / 3.4 us
    against 1.0 / 3.2 / 10 us for 64 / 220 / 700 values). The equal pass makes progress on
    repeated values."""
    while hi - lo > 16:
        mid = (lo + hi) >> 1
        a, b, c = v[lo], v[mid], v[hi]
        p = max(min(a, b), min(max(a, b), c))
        s = lo
        for i in range(lo, hi + 1):
            x = v[i]
            v[i] = v[s]
            v[s] = x
            s += x < p
        if k < s:
            hi = s - 1
            continue
        e = s
        for i in range(s, hi + 1):
            x = v[i]
            v[i] = v[e]
            v[e] = x
            e += x <= p
        if k < e:
            return
        lo = e
    for i in range(lo + 1, hi + 1):  # a few values left: insertion sort
        x = v[i]
        j = i - 1
        while j >= lo and v[j] > x:
            v[j + 1] = v[j]
            j -= 1
        v[j + 1] = x


_BRACKET_SAMPLE = 64  # values sampled to bracket a median (_median_k)
_BRACKET_HALF = 10  # the sample ranks taken either side of its middle


@kernel_helper
def _median_k(v, n):
    """np.median of v[:n] (n > 0) by selection; may reorder v[:n]. From 256 values on, two
    values of a strided sample bracket the median (Floyd and Rivest): one pass without branches
    copies the values between them aside, and only those are searched, unless the median lies
    outside (rarely), when all are. The same value either way: selection is exact."""
    k = n // 2
    lo, hi, r = 0, n - 1, k
    if n >= 256:
        s = _BRACKET_SAMPLE
        sample = np.empty(s)
        for i in range(s):
            sample[i] = v[(2 * i + 1) * n // (2 * s)]
        a, b = s // 2 - _BRACKET_HALF, s // 2 + _BRACKET_HALF - 1
        _select_k(sample, 0, s - 1, b)
        _select_k(sample, 0, b - 1, a)
        p_lo, p_hi = sample[a], sample[b]
        band = np.empty(n)
        below, m = 0, 0
        for i in range(n):
            x = v[i]
            below += x < p_lo
            band[m] = x  # kept only if inside: no branch to mispredict
            m += (x >= p_lo) & (x <= p_hi)
        if below + 1 - n % 2 <= k < below + m:  # rank k, and k-1 for an even n, inside
            v, lo, hi, r = band, 0, m - 1, k - below
    _select_k(v, lo, hi, r)
    if n % 2:
        return v[r]
    under = v[lo]
    for i in range(lo + 1, r):  # everything before r is <= v[r]: the largest is the (r-1)th
        if v[i] > under:
            under = v[i]
    return 0.5 * (under + v[r])


@kernel_helper
def _thin_median_k(buf, n, scratch):
    """_median(_thin(buf[:n])) (n > 0), using scratch; buf is left as it is."""
    step = n // 600 if n > 1200 else 1
    m = 0
    for i in range(0, n, step):
        scratch[m] = buf[i]
        m += 1
    return _median_k(scratch, m)


@kernel_helper
def _second_diff_sigmas_k(V, ok, bufs, scratch, scratch2, out):
    """_second_diff_sigma of each of the planes V[:4] with the valid pixels ``ok`` into out[:4]
    (the second differences of all four gathered in one pass; bufs: (4, n) scratch)."""
    h, w = ok.shape
    n = 0
    for i in range(0, h, 3):
        for j in range(w - 2):
            if ok[i, j] and ok[i, j + 1] and ok[i, j + 2]:
                for c in range(4):
                    bufs[c, n] = V[c, i, j] - 2 * V[c, i, j + 1] + V[c, i, j + 2]
                n += 1
    for j in range(0, w, 3):
        for i in range(h - 2):
            if ok[i, j] and ok[i + 1, j] and ok[i + 2, j]:
                for c in range(4):
                    bufs[c, n] = V[c, i, j] - 2 * V[c, i + 1, j] + V[c, i + 2, j]
                n += 1
    for c in range(4):
        out[c] = 0.0
    if n < 8:
        return
    step = n // 600 if n > 1200 else 1
    for c in range(4):
        m = 0
        for i in range(0, n, step):
            scratch[m] = bufs[c, i]
            scratch2[m] = bufs[c, i]
            m += 1
        med = _median_k(scratch2, m)
        for i in range(m):
            scratch2[i] = abs(scratch[i] - med)
        out[c] = MAD_TO_SIGMA * _median_k(scratch2, m) / np.sqrt(6.0)


@kernel_helper
def _box_sums_k(ok, V, nch, rad, R, S):
    """Box sums over the pixels ``ok`` in a (2 rad+1)^2 window: S[0] their count, S[c+1] the
    sum of plane V[c] rounded to float32 (R: scratch of S's shape), by running sums along
    rows, then columns. Like OpenCV's box filter in _local_means it sums float32 values in
    float64: exactly, unless a crop's values span more than 2^29, so the order does not
    matter, and a pixel taken out later can be subtracted (_box_remove_k)."""
    h, w = ok.shape
    line = np.zeros(w + 2 * rad)  # one row of values, between rad zeros each side
    acc = np.empty(w)
    for c in range(nch + 1):
        for i in range(h):  # rows: direct sums, vectorised across the row
            if c == 0:
                for j in range(w):
                    line[rad + j] = 1.0 if ok[i, j] else 0.0
            else:
                for j in range(w):
                    line[rad + j] = np.float32(V[c - 1, i, j]) if ok[i, j] else 0.0
            for j in range(w):
                R[c, i, j] = line[j]
            for t in range(1, 2 * rad + 1):
                for j in range(w):
                    R[c, i, j] += line[j + t]
        for j in range(w):  # columns: running sums, vectorised across the row
            acc[j] = 0.0
        for i in range(min(rad, h)):
            for j in range(w):
                acc[j] += R[c, i, j]
        for i in range(h):
            if i + rad < h:
                for j in range(w):
                    acc[j] += R[c, i + rad, j]
            for j in range(w):
                S[c, i, j] = acc[j]
            if i - rad >= 0:
                for j in range(w):
                    acc[j] -= R[c, i - rad, j]


@kernel_helper
def _box_remove_k(S, V, nch, rad, i, j):
    """Take pixel (i, j) out of the box sums S of _box_sums_k."""
    h, w = S.shape[1], S.shape[2]
    for ii in range(max(i - rad, 0), min(i + rad + 1, h)):
        for jj in range(max(j - rad, 0), min(j + rad + 1, w)):
            S[0, ii, jj] -= 1.0
    for c in range(nch):
        v = np.float64(np.float32(V[c, i, j]))
        for ii in range(max(i - rad, 0), min(i + rad + 1, h)):
            for jj in range(max(j - rad, 0), min(j + rad + 1, w)):
                S[c + 1, ii, jj] -= v


@kernel_helper
def _box_mean_k(S, c, i, j):
    """_local_means's mean of plane c at (i, j) from the box sums S: float32 quotient of the
    float32-rounded sums, widened."""
    den = max(np.float32(S[0, i, j]), np.float32(1e-6))
    return np.float64(np.float32(np.float32(S[c + 1, i, j]) / den))


@kernel_helper
def _gather_k(plane, ok, buf):
    """plane[ok] (row-major) into buf; returns the count."""
    h, w = ok.shape
    n = 0
    for i in range(h):
        for j in range(w):
            if ok[i, j]:
                buf[n] = plane[i, j]
                n += 1
    return n


@kernel
def _crop_kernel(depth, nocs, inst, r0, c0, st, rad, cx, cy, min_px, denoise_radius,
                 outlier_sigma, nocs_tolerance, noise_floor, edge_sigma):
    """What _extract_mosaic does for one crop (eroded, strided mask ``inst`` whose pixel (i,j)
    is image pixel (r0+i st, c0+j st)), with each box sum formed once and pixels dropped by
    the outlier and edge tests subtracted from it. Returns (status, rr, cc, d, p, xu, xv, cnt,
    sigma_d, sigma_p): status 0 too few usable pixels, 1 raw values kept, 2 denoised (xu, xv
    and cnt given); rr, cc the kept pixels of the crop in row-major order, and their values."""
    h, w = inst.shape
    ok = np.zeros((h, w), np.bool_)
    V = np.zeros((6, h, w))
    n_ok = 0
    lo, hi = -nocs_tolerance, 1 + nocs_tolerance
    for i in range(h):
        for j in range(w):
            if not inst[i, j]:
                continue
            y, x = r0 + i * st, c0 + j * st
            d = depth[y, x]
            if not (d > 0 and d < np.inf):
                continue
            good, nonzero = True, False
            for c in range(3):
                v = nocs[y, x, c]
                if not (v >= lo and v <= hi):  # false for NaN
                    good = False
                if v != 0:
                    nonzero = True
            if good and nonzero:
                ok[i, j] = True
                n_ok += 1
                V[0, i, j] = d
                for c in range(3):
                    V[c + 1, i, j] = nocs[y, x, c]
    e_i = np.zeros(0, np.int64)
    e_f = np.zeros(0)
    if n_ok < min_px:
        return 0, e_i, e_i, e_f, np.zeros((0, 3)), e_f, e_f, e_f, 0.0, 0.0
    size = max(((h + 2) // 3) * max(w - 2, 0) + ((w + 2) // 3) * max(h - 2, 0), h * w)
    buf, buf2, scratch, scratch2 = np.empty(size), np.empty(size), np.empty(size), np.empty(size)
    sig = np.empty(4)
    _second_diff_sigmas_k(V, ok, np.empty((4, size)), scratch, scratch2, sig)
    sd = sig[0]
    # The NOCS noise: the RMS over the channels, as np.mean of the three squares.
    sp = np.sqrt((sig[1] * sig[1] + sig[2] * sig[2] + sig[3] * sig[3]) / 3.0)
    n = _gather_k(V[0], ok, buf)
    depth_med = _thin_median_k(buf, n, scratch)
    if sd < noise_floor * depth_med:
        sd = 0.0
    if sp < 4 * noise_floor:
        sp = 0.0
    denoise = False
    S = np.zeros((0, h, w))
    nch = 4
    if denoise_radius > 0 or outlier_sigma > 0:
        denoise = denoise_radius > 0 and (sd > 0 or sp > 0)
    if denoise or (denoise_radius > 0 or outlier_sigma > 0) and (outlier_sigma > 0
                                                                  or edge_sigma > 0):
        if denoise:
            nch = 6
            for i in range(h):
                v = (i * st + r0) - cy
                for j in range(w):
                    V[4, i, j] = V[0, i, j] * ((j * st + c0) - cx)
                    V[5, i, j] = V[0, i, j] * v
        S = np.empty((nch + 1, h, w))
        _box_sums_k(ok, V, nch, rad, np.empty((nch + 1, h, w)), S)
    if outlier_sigma > 0:
        n = 0
        for i in range(h):
            for j in range(w):
                if ok[i, j]:
                    buf[n] = abs(V[0, i, j] - _box_mean_k(S, 0, i, j))
                    dp0 = V[1, i, j] - _box_mean_k(S, 1, i, j)
                    dp1 = V[2, i, j] - _box_mean_k(S, 2, i, j)
                    dp2 = V[3, i, j] - _box_mean_k(S, 3, i, j)
                    buf2[n] = np.sqrt(dp0 * dp0 + dp1 * dp1 + dp2 * dp2)
                    n += 1
        thr_d = outlier_sigma * max(MAD_TO_SIGMA * _thin_median_k(buf, n, scratch),
                                    1e-9 * depth_med)
        thr_p = outlier_sigma * max(MAD_TO_SIGMA * _thin_median_k(buf2, n, scratch), 1e-9)
        n2 = 0
        for k in range(n):
            if buf[k] <= thr_d and buf2[k] <= thr_p:
                n2 += 1
        if n2 >= min_px and n2 != n_ok:
            k = 0
            for i in range(h):
                for j in range(w):
                    if ok[i, j]:
                        if not (buf[k] <= thr_d and buf2[k] <= thr_p):
                            ok[i, j] = False
                            _box_remove_k(S, V, nch, rad, i, j)
                        k += 1
            n_ok = n2
    if edge_sigma > 0 and (denoise_radius > 0 or outlier_sigma > 0):
        md = np.zeros((h, w))
        for i in range(h):
            for j in range(w):
                if ok[i, j]:
                    md[i, j] = _box_mean_k(S, 0, i, j)
        g = np.zeros((h, w))
        n = 0
        for i in range(h):
            for j in range(w):
                gh = 0.0
                if 0 < j < w - 1 and ok[i, j - 1] and ok[i, j + 1]:
                    gh = abs(md[i, j + 1] - md[i, j - 1]) * 0.5
                gv = 0.0
                if 0 < i < h - 1 and ok[i - 1, j] and ok[i + 1, j]:
                    gv = abs(md[i + 1, j] - md[i - 1, j]) * 0.5
                g[i, j] = max(gh, gv)
                if ok[i, j] and g[i, j] > 0:
                    buf[n] = g[i, j]
                    n += 1
        if n >= 8:
            thr_g = (edge_sigma * MAD_TO_SIGMA * _thin_median_k(buf, n, scratch)
                     + noise_floor * depth_med)
            n2 = 0
            for i in range(h):
                for j in range(w):
                    if ok[i, j] and g[i, j] <= thr_g:
                        n2 += 1
            if n2 >= min_px:
                for i in range(h):
                    for j in range(w):
                        if ok[i, j] and not g[i, j] <= thr_g:
                            ok[i, j] = False
                            if denoise:
                                _box_remove_k(S, V, nch, rad, i, j)
                n_ok = n2
    if n_ok < min_px:
        return 0, e_i, e_i, e_f, np.zeros((0, 3)), e_f, e_f, e_f, 0.0, 0.0
    rr = np.empty(n_ok, np.int64)
    cc = np.empty(n_ok, np.int64)
    d = np.empty(n_ok)
    p = np.empty((n_ok, 3))
    k = 0
    for i in range(h):
        for j in range(w):
            if ok[i, j]:
                rr[k], cc[k] = i, j
                k += 1
    if not denoise:
        for k in range(n_ok):
            d[k] = V[0, rr[k], cc[k]]
            for c in range(3):
                p[k, c] = V[c + 1, rr[k], cc[k]]
        return 1, rr, cc, d, p, e_f, e_f, e_f, sd, sp
    xu = np.empty(n_ok)
    xv = np.empty(n_ok)
    cn = np.empty(n_ok)
    for k in range(n_ok):
        i, j = rr[k], cc[k]
        d[k] = _box_mean_k(S, 0, i, j)
        for c in range(3):
            p[k, c] = _box_mean_k(S, c + 1, i, j)
        xu[k] = _box_mean_k(S, 4, i, j) / d[k]
        xv[k] = _box_mean_k(S, 5, i, j) / d[k]
        cn[k] = np.float32(S[0, i, j])
    return 2, rr, cc, d, p, xu, xv, cn, sd, sp


@kernel_helper
def _eroded_crop_t(vals, iid, r0, r1, c0, c1, k, st):
    """_eroded_crop_k on the mask's values ``vals`` (unsigned integers)."""
    h, w = r1 - r0, c1 - c0
    a = np.empty((h, w), np.uint8)  # the instance's pixels of the box, then eroded along rows
    for i in range(h):
        row, ai = vals[r0 + i, c0:c1], a[i]
        for j in range(w):
            ai[j] = row[j] == iid
    if k > 0 and w > 0:
        b = np.empty(w, np.uint8)
        for i in range(h):
            ai = a[i]
            # k 3-wide erosions, the box's outside as background; (w + 1) // 2 of them
            # leave none of the row, so more cost time and change nothing.
            for _ in range(min(k, (w + 1) // 2)):
                b[0] = 0
                b[w - 1] = 0
                for j in range(1, w - 1):
                    b[j] = ai[j - 1] & ai[j] & ai[j + 1]
                ai[:] = b
    out = np.zeros(((h + st - 1) // st, (w + st - 1) // st), np.bool_)
    acc = np.empty(w, np.uint8)
    for q in range(out.shape[0]):  # down the columns, only for the rows kept
        i = q * st
        if i < k or i >= h - k:
            continue
        acc[:] = a[i - k]
        for ii in range(i - k + 1, i + k + 1):
            ai = a[ii]
            for j in range(w):
                acc[j] &= ai[j]
        for c in range(out.shape[1]):
            out[q, c] = acc[c * st] != 0
    return out


@kernel
def _eroded_crop_k(raw, itemsize, iid, r0, r1, c0, c1, k, st):
    """``(mask[r0:r1, c0:c1] == iid)`` eroded ``k`` times by a 3x3 square, the box's outside
    counting as background (cv2.erode with a zero border, as the numpy path does), then every
    st-th row and column; the mask seen as the bytes ``raw`` of ``itemsize``-byte native
    integers, read as unsigned (one compiled signature for every integer type). The 3x3 square
    is a 3-wide erosion along rows, then one down the columns (only for the rows kept), each in
    branch-free loops over contiguous rows."""
    if itemsize == 1:
        return _eroded_crop_t(raw, np.uint8(iid), r0, r1, c0, c1, k, st)
    if itemsize == 2:
        return _eroded_crop_t(raw.view(np.uint16), np.uint16(iid), r0, r1, c0, c1, k, st)
    if itemsize == 4:
        return _eroded_crop_t(raw.view(np.uint32), np.uint32(iid), r0, r1, c0, c1, k, st)
    return _eroded_crop_t(raw.view(np.uint64), np.uint64(iid), r0, r1, c0, c1, k, st)


@kernel
def _denoised_pick_k(pick, d, p, xu, xv, cn, var_d_px, var_p_px):
    """The rows ``pick`` of a denoised crop's output as an instance's arrays: (x, d, p, var_d,
    var_p), x = (xu, xv) and each variance the pixel's noise over its box count (at least 1),
    as _emit_compiled's numpy steps gave them, in one pass instead of seven gathers."""
    m = pick.size
    x = np.empty((m, 2))
    d_out, p_out, var_d, var_p = np.empty(m), np.empty((m, 3)), np.empty(m), np.empty(m)
    for k in range(m):
        i = pick[k]
        x[k, 0], x[k, 1] = xu[i], xv[i]
        d_out[k] = d[i]
        p_out[k, 0], p_out[k, 1], p_out[k, 2] = p[i, 0], p[i, 1], p[i, 2]
        c = cn[i] if cn[i] > 1.0 else 1.0
        var_d[k] = var_d_px / c
        var_p[k] = var_p_px / c
    return x, d_out, p_out, var_d, var_p


@kernel
def _calibrated_nocs_k(p, noise):
    """calibrated_nocs's new NOCS: the points shrunk towards their centre along each principal
    axis by the share of its variance left after ``noise``, in one 3x3 map."""
    n = p.shape[0]
    centre = np.zeros(3)
    for k in range(n):
        for a in range(3):
            centre[a] += p[k, a]
    centre /= n
    cov = np.zeros((3, 3))
    for k in range(n):
        q0, q1, q2 = p[k, 0] - centre[0], p[k, 1] - centre[1], p[k, 2] - centre[2]
        cov[0, 0] += q0 * q0
        cov[0, 1] += q0 * q1
        cov[0, 2] += q0 * q2
        cov[1, 1] += q1 * q1
        cov[1, 2] += q1 * q2
        cov[2, 2] += q2 * q2
    cov[1, 0], cov[2, 0], cov[2, 1] = cov[0, 1], cov[0, 2], cov[1, 2]
    cov /= n
    val, vec = np.linalg.eigh(cov)
    gain = np.empty(3)
    for a in range(3):
        gain[a] = max(val[a] - noise, 0.0) / max(val[a], 1e-300)
    A = np.zeros((3, 3))  # vec diag(gain) vec^T
    for a in range(3):
        for b in range(3):
            for c in range(3):
                A[a, b] += vec[a, c] * gain[c] * vec[b, c]
    out = np.empty((n, 3))
    for k in range(n):
        q0, q1, q2 = p[k, 0] - centre[0], p[k, 1] - centre[1], p[k, 2] - centre[2]
        for b in range(3):
            out[k, b] = centre[b] + q0 * A[0, b] + q1 * A[1, b] + q2 * A[2, b]
    return out


@kernel_helper
def _add_to_box(count, box, v, i, j):
    """Count pixel (i, j) for id v and widen its box."""
    count[v] += 1
    if i < box[v, 0]:
        box[v, 0] = i
    box[v, 1] = i + 1
    if j < box[v, 2]:
        box[v, 2] = j
    if j + 1 > box[v, 3]:
        box[v, 3] = j + 1


@kernel_helper
def _span_to_boxes(row, i, j0, j1, top, limit, count, box):
    """Count and box the ids of row i's columns j0..j1-1; True at the first id above top (a
    value up to ``limit``)."""
    for j in range(j0, j1):
        v = row[j]
        if v != 0:
            if v <= top:
                _add_to_box(count, box, np.int64(v), i, j)
            elif v <= limit:
                return True
    return False


@kernel_helper
def _ids_to_boxes_k(vals, words, top, limit, count, box):
    """Count and box the ids 1..top of the mask ``vals`` (unsigned, so negative ids are large
    and ignored); ``words``: the same rows as 8-byte words, or None. Background comes 8 bytes
    at a time: a zero word is skipped whole. Returns True, unfinished, at the first id above
    top (a value up to ``limit``, the type's largest positive one)."""
    h, w = vals.shape
    if words is None:
        for i in range(h):
            if _span_to_boxes(vals[i], i, 0, w, top, limit, count, box):
                return True
        return False
    per_word = w // words.shape[1]
    for i in range(h):
        wrow = words[i]
        for q in range(wrow.size):
            if wrow[q] != 0 and _span_to_boxes(vals[i], i, q * per_word, (q + 1) * per_word,
                                               top, limit, count, box):
                return True
    return False


@kernel
def _few_ids_k(raw, itemsize, top, signed):
    """Pixel count and half-open box (row0, row1, col0, col1) of each id 1..top in a mask of
    ``itemsize``-byte native integers seen as bytes ``raw``, read as unsigned integers of that
    size (negative values of a ``signed`` type are large, and ignored), and whether an id above
    top was met (then the counts are unfinished). Bytes, so that one compiled signature serves
    every integer type; 8-byte words of them where the rows allow."""
    h = raw.shape[0]
    w = raw.shape[1] // itemsize
    count = np.zeros(top + 1, np.int64)
    box = np.zeros((top + 1, 4), np.int64)
    for v in range(top + 1):
        box[v, 0], box[v, 2] = h, w
    words = raw.view(np.uint64) if raw.shape[1] % 8 == 0 and raw.ctypes.data % 8 == 0 else None
    if itemsize == 1:
        above = _ids_to_boxes_k(raw, words, np.uint8(top),
                                np.uint8(0x7F if signed else 0xFF), count, box)
    elif itemsize == 2:
        above = _ids_to_boxes_k(raw.view(np.uint16), words, np.uint16(top),
                                np.uint16(0x7FFF if signed else 0xFFFF), count, box)
    elif itemsize == 4:
        above = _ids_to_boxes_k(raw.view(np.uint32), words, np.uint32(top),
                                np.uint32(0x7FFFFFFF if signed else 0xFFFFFFFF), count, box)
    else:
        above = _ids_to_boxes_k(raw.view(np.uint64), words, np.uint64(top),
                                np.uint64(0x7FFFFFFFFFFFFFFF if signed else 0xFFFFFFFFFFFFFFFF),
                                count, box)
    return count, box, above
