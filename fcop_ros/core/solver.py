"""The fCOP minimal solver: focal length and object scale from triplets of correspondences.

For two pixels a, b of one object with image points x (pixels, relative to the principal
point), z-depths d (metres) and NOCS points p, the camera model d K^-1 [x; 1] = s R p + t
with K = diag(f, f, 1) gives, after differencing (removes t) and taking norms (removes R):

    s^2 ||p_a - p_b||^2 - ||d_a x_a - d_b x_b||^2 / f^2 = (d_a - d_b)^2

A triplet (i, j, k) gives three such rows for the pairs (i,j), (j,k), (i,k), linear in the
unknowns (s^2, 1/f^2). Everything here is vectorised over triplets; no Python loop.
"""
from __future__ import annotations

import numpy as np

# A triplet whose 2x2 normal matrix is closer to singular than this (relative to the product
# of its column norms) does not determine (s^2, 1/f^2) and is reported invalid.
_DEGENERATE_REL_DET = 1e-10


def solve_triplets(x: np.ndarray, d: np.ndarray, p: np.ndarray, triplets: np.ndarray):
    """Solve the minimal problem for every triplet at once.

    Args:
        x: (N, 2) image points in pixels, relative to the principal point.
        d: (N,) z-depth in metres (any consistent unit: a global scale cancels into s).
        p: (N, 3) NOCS points (any origin: only differences enter).
        triplets: (T, 3) integer indices into the N points.

    Returns:
        ``(focal, scale_sq, valid)``: focal (T,) in pixels, scale_sq (T,) the squared object
        scale s^2 in metres^2 per NOCS unit^2, and valid (T,) bool. Invalid entries (degenerate
        triplets: equal depths, pairs collinear with the optical centre, a singular system, or
        a non-positive s^2 or 1/f^2) hold 0.0 in focal and scale_sq, never NaN or inf.
    """
    x = np.asarray(x, dtype=np.float64)
    d = np.asarray(d, dtype=np.float64)
    p = np.asarray(p, dtype=np.float64)
    tri = np.asarray(triplets, dtype=np.intp).reshape(-1, 3)
    if x.ndim != 2 or x.shape[1] != 2 or d.shape != (x.shape[0],) or p.shape != (x.shape[0], 3):
        raise ValueError(f"solve_triplets expects x (N,2), d (N,), p (N,3); got {x.shape}, {d.shape}, {p.shape}")
    if tri.size and (tri.min() < 0 or tri.max() >= x.shape[0]):
        raise ValueError("solve_triplets: triplet index out of range")

    # Gather each triplet's points once; every pair term is then written out per component on
    # contiguous 1-D columns (reductions over a length-2/3 last axis are slow in numpy).
    i, j, k = tri[:, 0], tri[:, 1], tri[:, 2]
    ycols = (d * x[:, 0], d * x[:, 1])
    P = [[p[idx, c] for c in range(3)] for idx in (i, j, k)]
    Y = [[yc[idx] for yc in ycols] for idx in (i, j, k)]
    Dd = [d[idx] for idx in (i, j, k)]
    nocs_sq, image_sq, depth_sq = [], [], []
    for a, b in ((0, 1), (1, 2), (0, 2)):
        nocs_sq.append((P[a][0] - P[b][0]) ** 2 + (P[a][1] - P[b][1]) ** 2 + (P[a][2] - P[b][2]) ** 2)
        image_sq.append((Y[a][0] - Y[b][0]) ** 2 + (Y[a][1] - Y[b][1]) ** 2)
        depth_sq.append((Dd[a] - Dd[b]) ** 2)

    # Least squares of  s2 * nocs_sq - w * image_sq = depth_sq  over the three rows, with the
    # columns normalised so that the 2x2 normal equations stay well conditioned
    # (image_sq is ~1e6 times larger than nocs_sq in typical units).
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        na = np.sqrt(nocs_sq[0] ** 2 + nocs_sq[1] ** 2 + nocs_sq[2] ** 2)
        nb = np.sqrt(image_sq[0] ** 2 + image_sq[1] ** 2 + image_sq[2] ** 2)
        ok = (na > 0) & (nb > 0) & np.isfinite(na) & np.isfinite(nb)
        na = np.where(ok, na, 1.0)
        nb = np.where(ok, nb, 1.0)
        A = [v / na for v in nocs_sq]
        B = [v / nb for v in image_sq]
        saa = A[0] * A[0] + A[1] * A[1] + A[2] * A[2]
        sbb = B[0] * B[0] + B[1] * B[1] + B[2] * B[2]
        sab = A[0] * B[0] + A[1] * B[1] + A[2] * B[2]
        sac = A[0] * depth_sq[0] + A[1] * depth_sq[1] + A[2] * depth_sq[2]
        sbc = B[0] * depth_sq[0] + B[1] * depth_sq[1] + B[2] * depth_sq[2]
        det = saa * sbb - sab * sab
        ok &= det > _DEGENERATE_REL_DET * saa * sbb
        det = np.where(ok, det, 1.0)
        s2 = (sbb * sac - sab * sbc) / det / na
        w = (sab * sac - saa * sbc) / det / nb
        ok &= np.isfinite(s2) & np.isfinite(w) & (s2 > 0) & (w > 0)
        focal = np.where(ok, 1.0 / np.sqrt(np.where(ok, w, 1.0)), 0.0)
        ok &= np.isfinite(focal)
    focal = np.where(ok, focal, 0.0)
    scale_sq = np.where(ok, s2, 0.0)
    return focal, scale_sq, ok


def sample_triplets(n: int, count: int, rng: np.random.Generator) -> np.ndarray:
    """Draw ``count`` triplets of distinct indices in [0, n) uniformly (the paper's sampling)."""
    if n < 3 or count <= 0:
        return np.empty((0, 3), dtype=np.intp)
    i = rng.integers(0, n, count)
    j = rng.integers(0, n - 1, count)
    j += j >= i
    k = rng.integers(0, n - 2, count)
    lo, hi = np.minimum(i, j), np.maximum(i, j)
    k += k >= lo
    k += k >= hi
    return np.stack([i, j, k], axis=1)
