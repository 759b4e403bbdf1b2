"""The fCOP minimal solver: focal length and object scale from triplets of correspondences.

For two pixels a, b of one object with image points x (pixels, relative to the principal
point), z-depths d (metres) and NOCS points p, the camera model d K^-1 [x; 1] = s R p + t
with K = diag(f, f, 1) gives, after differencing (removes t) and taking norms (removes R):

    s^2 ||p_a - p_b||^2 - ||d_a x_a - d_b x_b||^2 / f^2 = (d_a - d_b)^2

A triplet (i, j, k) gives three such rows for the pairs (i,j), (j,k), (i,k), linear in the
unknowns (s^2, 1/f^2). The numpy path is vectorised over triplets (a chunk at a time); the
compiled kernel (:mod:`.compiled`) makes one pass over them with the same arithmetic in the
same order, so both give the same bits.
"""
from __future__ import annotations

import numpy as np

from . import compiled

# A triplet whose 2x2 normal matrix is closer to singular than this (its determinant relative
# to the product of its diagonal, which is unit-free) does not determine (s^2, 1/f^2) and is
# reported invalid.
_DEGENERATE_REL_DET = 1e-10
_CHUNK = 8192  # triplets solved together: 64 KiB per temporary, which stays in cache


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
        raise ValueError(f"solve_triplets expects x (N,2), d (N,), p (N,3); got {x.shape}, "
                         f"{d.shape}, {p.shape}")
    if tri.size and (tri.min() < 0 or tri.max() >= x.shape[0]):
        raise ValueError("solve_triplets: triplet index out of range")

    t = tri.shape[0]
    focal, scale_sq, valid = np.empty(t), np.empty(t), np.empty(t, dtype=bool)
    if compiled.ENABLED:
        # Contiguous inputs: one compiled signature, whatever views the caller passes.
        none = np.empty(0, dtype=np.intp)
        _triplets_kernel(np.ascontiguousarray(x), np.ascontiguousarray(d),
                         np.ascontiguousarray(p), np.ascontiguousarray(tri), none, none, False,
                         -np.inf, np.inf, focal, scale_sq, valid, none)
        return focal, scale_sq, valid
    # Every pair term is written out per component on 1-D columns (reductions over a length-2/3
    # last axis are slow in numpy), a chunk of triplets at a time so that the temporaries stay
    # in cache; the columns are gathered straight from the (strided) input, which is not copied.
    cols = (p[:, 0], p[:, 1], p[:, 2], x[:, 0], x[:, 1], d)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        for s in range(0, t, _CHUNK):
            e = min(s + _CHUNK, t)
            _solve_chunk(cols, tri[s:e].T, focal[s:e], scale_sq[s:e], valid[s:e])
    return focal, scale_sq, valid


def _square_distance(g, a, b, comps):
    """Sum over the columns ``comps`` of (point a - point b)^2, in one new array."""
    out = g[a][comps[0]] - g[b][comps[0]]
    out *= out
    for c in comps[1:]:
        t = g[a][c] - g[b][c]
        t *= t
        out += t
    return out


def _dot3(u, v):
    out = u[0] * v[0]
    out += u[1] * v[1]
    out += u[2] * v[2]
    return out


def _solve_chunk(cols, idx, focal, scale_sq, valid):
    """Solve the triplets idx (3, T) into the views focal, scale_sq and valid (T,)."""
    g = []
    for i in idx:  # each triplet's k-th point: NOCS, camera-plane point d x, depth
        px, py, pz, xx, xy, dd = (c[i] for c in cols)
        xx *= dd
        xy *= dd
        g.append((px, py, pz, xx, xy, dd))
    pairs = ((0, 1), (1, 2), (0, 2))
    nocs_sq = [_square_distance(g, i, j, (0, 1, 2)) for i, j in pairs]  # ||p_i - p_j||^2
    image_sq = [_square_distance(g, i, j, (3, 4)) for i, j in pairs]  # ||d_i x_i - d_j x_j||^2
    depth_sq = [_square_distance(g, i, j, (5,)) for i, j in pairs]  # (d_i - d_j)^2
    # Least squares of  s2 * nocs_sq - w * image_sq = depth_sq  over the three rows, with the
    # columns normalised so that the 2x2 normal equations stay well conditioned (image_sq is
    # ~1e6 times larger than nocs_sq in typical units). An empty or non-finite column gives
    # NaN or a zero determinant below, so the tests at the end reject it.
    na = np.sqrt(_dot3(nocs_sq, nocs_sq))
    nb = np.sqrt(_dot3(image_sq, image_sq))
    A = [np.divide(v, na, out=v) for v in nocs_sq]
    B = [np.divide(v, nb, out=v) for v in image_sq]
    saa, sbb, sab = _dot3(A, A), _dot3(B, B), _dot3(A, B)
    sac, sbc = _dot3(A, depth_sq), _dot3(B, depth_sq)
    det = saa * sbb
    det -= sab * sab
    ok = det > _DEGENERATE_REL_DET * saa * sbb
    s2 = sbb * sac
    s2 -= sab * sbc
    s2 /= det
    np.divide(s2, na, out=scale_sq)
    w = sab * sac
    w -= saa * sbc
    w /= det
    w /= nb
    ok &= np.isfinite(scale_sq)
    ok &= np.isfinite(w)
    ok &= scale_sq > 0
    ok &= w > 0
    np.sqrt(w, out=w)
    np.divide(1.0, w, out=focal)
    ok &= np.isfinite(focal)
    bad = ~ok
    focal[bad] = 0.0
    scale_sq[bad] = 0.0
    valid[...] = ok


_BLOCK = 64  # triplets the kernel gathers, then solves in one vectorised loop


@compiled.kernel
def _triplets_kernel(x, d, p, tri, base, group, shift, lo, hi, focal, scale_sq, valid, owner):
    """The compiled triplet solve: ``_solve_chunk``'s arithmetic operation for operation in the
    same order (no fused multiply-adds), so its numbers have the same bits.

    A block of triplets is gathered first, then solved in a loop of plain arithmetic without
    branches (``v - v == 0`` is isfinite), which the compiler turns into vector instructions.
    ``solve_triplets`` passes absolute triplets (base and group empty) and gets every result
    at its row (owner empty). ``object_votes`` passes raw draws with each row's object (group)
    and its first point (base), ``shift`` to make them distinct as ``sample_triplets`` does,
    and gets only the valid focal lengths in [lo, hi], packed to the front with their object
    in owner. Returns the number of results written.
    """
    g = np.empty((18, _BLOCK))  # per row: NOCS, d x and d of the triplet's three points
    bf, bs = np.empty(_BLOCK), np.empty(_BLOCK)
    bok = np.empty(_BLOCK, dtype=np.bool_)
    m = 0
    for s0 in range(0, tri.shape[0], _BLOCK):
        size = min(_BLOCK, tri.shape[0] - s0)
        for q in range(size):
            t = s0 + q
            i, j, k = tri[t, 0], tri[t, 1], tri[t, 2]
            if shift:  # sample_triplets' shifts, one triplet at a time
                j += 1 if j >= i else 0
                k += 1 if k >= min(i, j) else 0
                k += 1 if k >= max(i, j) else 0
            if base.size:
                i, j, k = i + base[t], j + base[t], k + base[t]
            for c, r in enumerate((i, j, k)):
                g[6 * c, q], g[6 * c + 1, q], g[6 * c + 2, q] = p[r, 0], p[r, 1], p[r, 2]
                g[6 * c + 3, q], g[6 * c + 4, q] = x[r, 0] * d[r], x[r, 1] * d[r]
                g[6 * c + 5, q] = d[r]
        for q in range(size):
            # Rows of the pairs (i,j), (j,k), (i,k): NOCS, image (camera plane) and depth.
            u, v, w = g[0, q] - g[6, q], g[1, q] - g[7, q], g[2, q] - g[8, q]
            n0 = u * u + v * v + w * w
            u, v, w = g[6, q] - g[12, q], g[7, q] - g[13, q], g[8, q] - g[14, q]
            n1 = u * u + v * v + w * w
            u, v, w = g[0, q] - g[12, q], g[1, q] - g[13, q], g[2, q] - g[14, q]
            n2 = u * u + v * v + w * w
            u, v = g[3, q] - g[9, q], g[4, q] - g[10, q]
            m0 = u * u + v * v
            u, v = g[9, q] - g[15, q], g[10, q] - g[16, q]
            m1 = u * u + v * v
            u, v = g[3, q] - g[15, q], g[4, q] - g[16, q]
            m2 = u * u + v * v
            u, v, w = g[5, q] - g[11, q], g[11, q] - g[17, q], g[5, q] - g[17, q]
            c0, c1, c2 = u * u, v * v, w * w
            na = np.sqrt(n0 * n0 + n1 * n1 + n2 * n2)
            nb = np.sqrt(m0 * m0 + m1 * m1 + m2 * m2)
            a0, a1, a2 = n0 / na, n1 / na, n2 / na
            b0, b1, b2 = m0 / nb, m1 / nb, m2 / nb
            saa = a0 * a0 + a1 * a1 + a2 * a2
            sbb = b0 * b0 + b1 * b1 + b2 * b2
            sab = a0 * b0 + a1 * b1 + a2 * b2
            sac = a0 * c0 + a1 * c1 + a2 * c2
            sbc = b0 * c0 + b1 * c1 + b2 * c2
            det = saa * sbb - sab * sab
            s2 = (sbb * sac - sab * sbc) / det / na
            w = (sab * sac - saa * sbc) / det / nb
            f = 1.0 / np.sqrt(w)
            ok = ((det > _DEGENERATE_REL_DET * saa * sbb) & (s2 - s2 == 0) & (w - w == 0)
                  & (s2 > 0) & (w > 0) & (f - f == 0))
            bf[q] = f if ok else 0.0
            bs[q] = s2 if ok else 0.0
            bok[q] = ok
        for q in range(size):
            if owner.size == 0:
                focal[m], scale_sq[m], valid[m] = bf[q], bs[q], bok[q]
                m += 1
            elif bok[q] and bf[q] >= lo and bf[q] <= hi:
                focal[m], scale_sq[m], valid[m] = bf[q], bs[q], True
                owner[m] = group[s0 + q]
                m += 1
    return m


@compiled.kernel
def _votes_kernel(x, d, p, sizes, count, rng, lo, hi):
    """object_votes' compiled path: ``_draw``'s numbers for every object of at least three
    points, drawn from the same generator (numba's Generator.integers gives numpy's numbers
    and advances its state alike), then solved by _triplets_kernel; without a Python call per
    object and array (0.18 ms of a 640x480 frame's 0.6)."""
    nbig = 0
    for q in range(sizes.size):
        if sizes[q] >= 3:
            nbig += 1
    total = nbig * count
    raw = np.empty((total, 3), np.intp)
    base = np.empty(total, np.intp)
    group = np.empty(total, np.intp)
    start = 0
    r = 0
    for q in range(sizes.size):
        n = sizes[q]
        if n >= 3:
            for c in range(3):  # i in [0, n), j in [0, n-1), k in [0, n-2), as _draw
                draw = rng.integers(0, n - c, count)
                for t in range(count):
                    raw[r + t, c] = draw[t]
            for t in range(count):
                base[r + t] = start
                group[r + t] = q
            r += count
        start += n
    focal, scale_sq = np.empty(total), np.empty(total)
    valid, owner = np.empty(total, np.bool_), np.empty(total, np.intp)
    m = _triplets_kernel(x, d, p, raw, base, group, True, lo, hi, focal, scale_sq, valid, owner)
    return focal[:m].copy(), owner[:m].copy()


def sample_triplets(n: int, count: int, rng: np.random.Generator) -> np.ndarray:
    """Draw ``count`` triplets of distinct indices in [0, n) uniformly (the paper's sampling)."""
    if n < 3 or count <= 0:
        return np.empty((0, 3), dtype=np.intp)
    i, j, k = _draw(n, count, rng)
    j += j >= i
    lo, hi = np.minimum(i, j), np.maximum(i, j)
    k += k >= lo
    k += k >= hi
    return np.stack([i, j, k], axis=1)


def _draw(n: int, count: int, rng: np.random.Generator):
    """The random numbers of ``sample_triplets`` (n >= 3): i in [0, n), j in [0, n-1) and
    k in [0, n-2), which it then shifts past the smaller indices to make them distinct."""
    i = rng.integers(0, n, count)
    j = rng.integers(0, n - 1, count)
    k = rng.integers(0, n - 2, count)
    return i, j, k


def object_votes(xs, ds, ps, count: int, rng: np.random.Generator, focal_range):
    """The estimator's votes: ``count`` random triplets on every object (``sample_triplets``,
    object after object, from ``rng``), solved; the valid focal lengths inside focal_range.

    xs, ds, ps: per object its x (N_o,2), d (N_o,) and p (N_o,3) as for ``solve_triplets``;
    objects of fewer than three points draw nothing. Returns (focal (V,), owner (V,)), owner
    the index of the vote's object. The compiled path draws the same numbers and solves each
    triplet as it shifts it, without the triplet array or the invalid votes.
    """
    lo, hi = (float(v) for v in focal_range)
    count = max(int(count), 0)
    sizes = [len(v) for v in ds]
    x, d, p = (np.ascontiguousarray(np.concatenate(v), dtype=np.float64) for v in (xs, ds, ps))
    if compiled.ENABLED and type(rng) is np.random.Generator:
        return _votes_kernel(x, d, p, np.array(sizes, dtype=np.intp), count, rng, lo, hi)
    offsets = np.concatenate([[0], np.cumsum(sizes)[:-1]]).astype(np.intp)
    tri = np.concatenate([sample_triplets(n, count, rng) + off for n, off in zip(sizes, offsets)])
    owner = np.repeat(np.arange(len(sizes)), [count if n >= 3 else 0 for n in sizes])
    f, _, ok = solve_triplets(x, d, p, tri)
    ok &= (f >= lo) & (f <= hi)
    return f[ok], owner[ok]
