"""Per-object maximum-likelihood fit of the focal length and the object's similarity.

For one object the model is  X_i = s R (p_i - 0.5) + t  (camera frame), observed as the pixel
x_i = f X_i[:2] / X_i[2] (exact pixel centres) and the depth d_i = X_i[2]. The residuals are
the reprojection error (pixels) and the depth error (metres), each weighted by its own noise
level, estimated from the object's residuals. Depth errors enter linearly, so zero-mean depth
noise does not bias the fit, unlike fits built on squared distances or on residuals measured
in NOCS units (errors in the regressor inflate an object's relief and shorten f).

R is any orthogonal matrix: the distance constraint of fCOP holds for reflections too, so a
mirrored NOCS (a swapped channel order or a flipped axis) gives the same focal length; the fit
reports it (``mirrored``) so that no pose is made from it.

Every object is fitted on its own (its own focal length), all objects at once: the arrays are
padded to (objects, pixels) and every step is a batched numpy operation. Gauss-Newton with a
little Levenberg damping and Cauchy weights against outliers. Where the compiled kernels are on
(``compiled.ENABLED``), one kernel does the same mathematics in loops over each object's pixels,
forming the normal equations from the Jacobian's non-zero entries only.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import compiled
from .compiled import kernel, kernel_helper
from .correspondences import _median_k
from .robust import MAD_TO_SIGMA

_CAUCHY = 3.0  # robust weight 1 / (1 + (e / c)^2) of a pixel whose normalised residual is e


@dataclass
class ObjectFits:
    """Per-object results, stacked over objects (O,).

    focal: px (the object's own estimate, or the fixed focal); var_log_focal: variance of log f
    from the fit's curvature (inf when fixed or degenerate); scale, rotation (O,3,3), translation
    (O,3); quality: share of the object's 3D variance the similarity explains (1 = perfect, ~0 for
    NOCS unrelated to the shape); mirrored: the best orthogonal fit is a reflection and explains
    clearly more than the best rotation; sigma_px, sigma_depth: residual noise levels (px, m);
    inlier_ratio: share of pixels with a Cauchy weight above 0.5; pixels: pixels used; ok: fit
    usable; relief: the fitted object's depth relief (standard deviation of its model points' z,
    metres); tilt: (O,2) the fitted relative depth-error gradient over the object (per standard
    deviation of its image extent along x and y; zeros without ``depth_tilt``); tilt_chi2: its
    chi-square (2 degrees of freedom) against zero.
    """

    focal: np.ndarray
    var_log_focal: np.ndarray
    scale: np.ndarray
    rotation: np.ndarray
    translation: np.ndarray
    quality: np.ndarray
    mirrored: np.ndarray
    sigma_px: np.ndarray
    sigma_depth: np.ndarray
    inlier_ratio: np.ndarray
    pixels: np.ndarray
    ok: np.ndarray
    relief: np.ndarray
    tilt: np.ndarray
    tilt_chi2: np.ndarray


def _pad(instances, max_pixels: int, rng: np.random.Generator):
    """(O, M) padded x, d, p (centred NOCS) and validity, at most ``max_pixels`` per object."""
    m = min(max(len(i.d) for i in instances), max_pixels)
    o = len(instances)
    X = np.zeros((o, m, 2))
    D = np.ones((o, m))
    P = np.zeros((o, m, 3))
    V = np.zeros((o, m), dtype=bool)
    for k, inst in enumerate(instances):
        n = len(inst.d)
        pick = rng.choice(n, m, replace=False) if n > m else np.arange(n)
        if compiled.ENABLED and _plain_rows(inst.x, inst.d, inst.p):
            _pad_rows_k(X, D, P, V, k, inst.x, inst.d, inst.p, pick)
            continue
        k_n = len(pick)
        X[k, :k_n], D[k, :k_n], P[k, :k_n] = inst.x[pick], inst.d[pick], inst.p[pick] - 0.5
        V[k, :len(pick)] = True
    return X, D, P, V


def _plain_rows(*arrays) -> bool:
    """Whether the arrays are C-contiguous float64, the one signature _pad_rows_k is compiled
    for."""
    return all(isinstance(a, np.ndarray) and a.dtype == np.float64 and a.flags.c_contiguous
               for a in arrays)


@kernel
def _pad_rows_k(X, D, P, V, k, x, d, p, pick):
    """_pad's rows of object k: x, d and p - 0.5 at the pixels ``pick``, marked valid, in one
    pass instead of three fancy-index gathers and four slice assignments."""
    for r in range(pick.size):
        i = pick[r]
        X[k, r, 0], X[k, r, 1] = x[i, 0], x[i, 1]
        D[k, r] = d[i]
        P[k, r, 0], P[k, r, 1], P[k, r, 2] = p[i, 0] - 0.5, p[i, 1] - 0.5, p[i, 2] - 0.5
        V[k, r] = True


def _orthogonal_fit(P, Y, W, proper: bool):
    """Weighted similarity Y ~ s Q P + t over orthogonal Q, batched over objects.

    Returns (s, Q, t, quality, mirrored): quality = explained share of Y's variance by the best
    orthogonal map; mirrored where that map is a reflection that explains clearly more (0.2 of
    the variance) than the best rotation. With ``proper``, Q is a rotation except where mirrored;
    else the best orthogonal map (the focal length does not care)."""
    wn = W / np.maximum(W.sum(1, keepdims=True), 1e-300)
    wr = wn[:, None, :]
    mp = (wr @ P)[:, 0]
    my = (wr @ Y)[:, 0]
    pc, yc = P - mp[:, None], Y - my[:, None]
    cov = np.swapaxes(yc * wn[..., None], 1, 2) @ pc
    vp = (wr @ (pc * pc))[:, 0].sum(-1)
    vy = (wr @ (yc * yc))[:, 0].sum(-1)
    U, S, Vt = np.linalg.svd(cov)
    Q = U @ Vt
    det = np.linalg.det(Q)
    total = S.sum(-1)
    proper_total = total - np.where(det < 0, 2 * S[:, 2], 0.0)
    denom = np.maximum(vp * vy, 1e-300)
    quality = total ** 2 / denom
    quality_proper = np.maximum(proper_total, 0) ** 2 / denom
    mirrored = (det < 0) & (quality - quality_proper > 0.2)
    # With ``proper``: a rotation unless only a reflection fits (a symmetric object fits both
    # about as well).
    if proper:
        fix = np.ones_like(S)
        fix[:, 2] = np.where(mirrored, 1.0, np.sign(det))
        Q = (U * fix[:, None, :]) @ Vt
        total = np.where(mirrored, total, proper_total)
    s = np.where(vp > 0, total / np.maximum(vp, 1e-300), 0.0)
    t = my - s[:, None] * np.einsum("oij,oj->oi", Q, mp)
    return s, Q, t, np.clip(quality, 0.0, 1.0), mirrored


def _row_median(res, valid):
    """Median of each row's valid, non-NaN entries (np.nanmedian's value); 0 for an empty row."""
    use = valid & ~np.isnan(res)
    n = use.sum(1)
    srt = np.sort(np.where(use, res, np.inf), axis=1)
    rows = np.arange(res.shape[0])
    med = (srt[rows, np.maximum((n - 1) // 2, 0)] + srt[rows, n // 2]) / 2
    return np.where(n > 0, med, 0.0)


def _clip(v, bound: float):
    """np.clip(v, -bound, bound) without np.clip's overhead on small arrays."""
    return np.minimum(np.maximum(v, -bound), bound)


def _rodrigues(w):
    """Rotation matrices exp([w]x) = cos(th) I + sin(th) [k]x + (1 - cos(th)) k k^T for w (O,3),
    th = |w|, k = w / th."""
    th = np.sqrt(np.add.reduce(w * w, axis=-1))
    k = w / np.where(th > 0, th, 1.0)[:, None]
    s, c = np.sin(th), np.cos(th)
    ks = k * s[:, None]
    R = (k * (1.0 - c)[:, None])[:, :, None] * k[:, None, :]
    R[:, 0, 0] += c
    R[:, 1, 1] += c
    R[:, 2, 2] += c
    R[:, 0, 1] -= ks[:, 2]
    R[:, 0, 2] += ks[:, 1]
    R[:, 1, 0] += ks[:, 2]
    R[:, 1, 2] -= ks[:, 0]
    R[:, 2, 0] -= ks[:, 1]
    R[:, 2, 1] += ks[:, 0]
    return R


def refit_log_focal_change(moved, f0: float, seed: int, options, logf, step: float
                           ) -> np.ndarray:
    """(O,) forward difference (log f' - ``logf``) / ``step`` of each object's focal length, f'
    from its fit redone on ``moved`` (its pixels moved by one ``step`` of some error; the same
    pixels as the fit ``logf`` came from, by ``seed``); 0 where the refit fails. ``options``:
    the fit's settings (an EstimatorOptions)."""
    fits = fit_objects(moved, f0, max_pixels=options.fit_pixels, depth_tilt=options.depth_tilt,
                       iterations=options.fit_iterations, rng=np.random.default_rng(seed))
    g = (np.where(fits.ok, np.log(fits.focal), np.nan) - logf) / step
    return np.where(np.isfinite(g), g, 0.0)


def fit_objects(instances, focal0: float, fix_focal: bool = False, iterations: int = 12,
                max_pixels: int = 600, depth_tilt: bool = True, proper: bool = False,
                rng: np.random.Generator | None = None) -> ObjectFits:
    """Fit every instance's focal length (or only its pose, with ``fix_focal``) and similarity.

    instances: items with x (n,2) px from the principal point, d (n,) metres, p (n,3) NOCS;
    focal0: starting focal length (px), also the fixed value with ``fix_focal``; proper: fit
    rotations (for poses) rather than any orthogonal map (for the focal length) where a rotation
    fits about as well.
    """
    rng = np.random.default_rng(0) if rng is None else rng
    X, D, P, V = _pad(instances, max_pixels, rng)
    if compiled.ENABLED:
        n = V.sum(1)
        (logf, var, logs, Rm, t, quality, mirrored, sig_px, sig_d, inliers, relief, tilt,
         tilt_chi2) = _fit_kernel(X, D, P, n, float(focal0), bool(fix_focal), int(iterations),
                                  bool(depth_tilt), bool(proper))
        ok = (np.isfinite(logf) & np.isfinite(logs) & np.all(np.isfinite(t), -1)
              & (t[:, 2] > 0) & (n >= 6))
        return ObjectFits(np.exp(logf), var, np.exp(logs), Rm, t, quality, mirrored, sig_px, sig_d,
                          inliers / np.maximum(n, 1), n, ok, relief, tilt, tilt_chi2)
    o, m = D.shape
    Vf = V.astype(np.float64)
    logf = np.full(o, np.log(focal0))
    # Start: the best orthogonal similarity between NOCS and the back-projection at focal0,
    # twice, with a robust weight from the first fit's residuals.
    Y = np.concatenate([X * (D / focal0)[..., None], D[..., None]], axis=-1)
    W = Vf.copy()
    for _ in range(2):
        s, Q, t, quality, mirrored = _orthogonal_fit(P, Y, W, proper)
        diff = Y - (s[:, None, None] * (P @ np.swapaxes(Q, 1, 2)) + t[:, None])
        res = np.sqrt((diff * diff).sum(-1))
        med = _row_median(res, V)
        W = Vf / (1.0 + (res / np.maximum(_CAUCHY * MAD_TO_SIGMA * med, 1e-12)[:, None]) ** 2)
    logs = np.log(np.maximum(s, 1e-12))
    Rm = Q
    npar = (7 if fix_focal else 8) + (2 if depth_tilt else 0)
    # Image position over each object, centred and scaled to about +-1: the depth tilt's regressor.
    cen = (X * Vf[..., None]).sum(1) / np.maximum(Vf.sum(1), 1)[:, None]
    span = np.sqrt((((X - cen[:, None]) ** 2).sum(-1) * Vf).sum(1) / np.maximum(Vf.sum(1), 1))
    U = (X - cen[:, None]) / np.maximum(span, 1e-9)[:, None, None] * Vf[..., None]
    # From here on component-major (O, components, M): every component is a contiguous row,
    # the Jacobian's rows are filled by slices, and J^T W J is one batched product.
    Xt = np.ascontiguousarray(np.swapaxes(X, 1, 2))
    Pt = np.ascontiguousarray(np.swapaxes(P, 1, 2))
    Ut = np.ascontiguousarray(np.swapaxes(U, 1, 2))
    tilt = np.zeros((o, 2))
    sig_px = np.full(o, 1.0)
    sig_d = np.full(o, 1e-3)
    w_rob = W  # zero off the valid pixels, like Vf
    lam = 1e-6
    diag = np.arange(npar)
    H = np.zeros((o, npar, npar))
    # The Jacobian of the predictions (u, v, d) in the parameters [log f], log s, w (3), t (3),
    # [tilt (2)], parameter-major (O, npar, 3, M); its entries that are always zero are set once.
    J = np.zeros((o, npar, 3, m))
    Jf = J.reshape(o, npar, 3 * m)
    r = np.empty((o, 3, m))  # residuals of u, v, d
    k0 = 0 if fix_focal else 1
    for it in range(iterations):
        f = np.exp(logf)
        q = (Rm * np.exp(logs)[:, None, None]) @ Pt  # s R (p - 0.5), (O, 3, M)
        Xc = q + t[..., None]
        zc = Xc[:, 2]
        z = np.where(np.abs(zc) > 1e-9, zc, 1e-9)
        iz = 1.0 / z
        uvh = Xc[:, :2] * (f[:, None] * iz)[:, None]  # predicted u, v
        gain = 1.0 + (Ut[:, 0] * tilt[:, 0, None] + Ut[:, 1] * tilt[:, 1, None])
        np.subtract(Xt, uvh, out=r[:, :2])
        np.subtract(D, zc * gain, out=r[:, 2])
        r2 = r * r
        # Noise levels from the robustly weighted residuals (with floors: exact data stay finite).
        wsum = np.maximum(w_rob.sum(1), 1e-300)
        ss = (r2 @ w_rob[..., None])[..., 0]  # (O, 3) weighted sums of squares
        sig_px = np.sqrt(np.maximum((ss[:, 0] + ss[:, 1]) / (2 * wsum), (1e-6) ** 2))
        sig_d = np.sqrt(np.maximum(ss[:, 2] / wsum, (1e-7 * t[:, 2]) ** 2))
        e2_w = np.empty((o, 1, 3))  # r2 -> (e / c)^2: 1 / (2 sigma_px^2 c^2) and 1 / (sigma_d c)^2
        e2_w[:, 0, 0] = 0.5 / _CAUCHY ** 2 / sig_px ** 2
        e2_w[:, 0, 1] = e2_w[:, 0, 0]
        e2_w[:, 0, 2] = 1.0 / _CAUCHY ** 2 / sig_d ** 2
        e2 = e2_w @ r2
        w_rob = Vf / (1.0 + e2[:, 0])
        if it == iterations - 1:
            break
        # The Jacobian is formed already scaled by the square roots of the row weights
        # w_rob / sigma^2 (su for u and v, sd for d), folded into the factors it is built from,
        # so that J^T W J and J^T W r are plain products, without a weighted copy.
        sw = np.sqrt(w_rob)
        su = sw * (1.0 / sig_px)[:, None]
        sd = sw * (1.0 / sig_d)[:, None]
        # d(prediction)/dX rows for u, v, d times dX/d(log s, w, t) = [q, -[q]x, I], with
        # a = f/z, (uz, vz) = (u, v)/z and the zero and unit entries multiplied out.
        a = f[:, None] * iz * su
        aq = q * a[:, None]  # a qx, a qy, a qz
        uvz = uvh * (iz * su)[:, None]  # uz, vz
        B = uvz[:, :, None] * q[:, None]  # (O, 2, 3, M): [uz, vz] x [qx, qy, qz]
        gs = gain * sd
        gq = q * gs[:, None]
        if not fix_focal:
            np.multiply(uvh, su[:, None], out=J[:, 0, :2])
        np.subtract(aq[:, :2], B[:, :, 2], out=J[:, k0, :2])  # log s
        J[:, k0, 2] = gq[:, 2]
        np.negative(B[:, :, 1], out=J[:, k0 + 1, :2])  # w_x
        J[:, k0 + 1, 1] -= aq[:, 2]
        J[:, k0 + 1, 2] = gq[:, 1]
        J[:, k0 + 2, :2] = B[:, :, 0]  # w_y
        J[:, k0 + 2, 0] += aq[:, 2]
        np.negative(gq[:, 0], out=J[:, k0 + 2, 2])
        np.negative(aq[:, 1], out=J[:, k0 + 3, 0])  # w_z
        J[:, k0 + 3, 1] = aq[:, 0]
        J[:, k0 + 4, 0] = a  # t
        J[:, k0 + 5, 1] = a
        np.negative(uvz, out=J[:, k0 + 6, :2])
        J[:, k0 + 6, 2] = gs
        if depth_tilt:
            np.multiply(Ut, (z * sd)[:, None], out=J[:, k0 + 7:, 2])
        rs = np.empty_like(r)  # the residuals scaled alike
        np.multiply(r[:, :2], su[:, None], out=rs[:, :2])
        np.multiply(r[:, 2], sd, out=rs[:, 2])
        H = Jf @ np.swapaxes(Jf, 1, 2)
        g = (Jf @ rs.reshape(o, 3 * m, 1))[..., 0]
        Hd = H.copy()
        Hd[:, diag, diag] += lam * np.maximum(H[:, diag, diag], 1e-12)
        try:
            step = np.linalg.solve(Hd, g[..., None])[..., 0]
        except np.linalg.LinAlgError:
            break
        step = np.where(np.isfinite(step), step, 0.0)
        if not fix_focal:
            logf = logf + _clip(step[:, 0], 0.3)
            step = step[:, 1:]
        logs = logs + _clip(step[:, 0], 0.3)
        Rm = _rodrigues(_clip(step[:, 1:4], 0.5)) @ Rm
        t = t + step[:, 4:7]
        if depth_tilt:
            tilt = tilt + _clip(step[:, 7:9], 0.05)
    with np.errstate(all="ignore"):
        try:
            cov = np.linalg.inv(H)
        except np.linalg.LinAlgError:
            cov = np.full(H.shape, np.inf)
    var = np.full(o, np.inf) if fix_focal else cov[:, 0, 0]
    tilt_chi2 = np.zeros(o)
    if depth_tilt:
        ct = cov[:, -2:, -2:]
        with np.errstate(all="ignore"):
            tilt_chi2 = np.einsum("oi,oij,oj->o", tilt, np.linalg.pinv(ct), tilt)
    var = np.where(np.isfinite(var) & (var > 0), var, np.inf)
    ok = (np.isfinite(logf) & np.isfinite(logs) & np.all(np.isfinite(t), -1) & (t[:, 2] > 0)
          & (V.sum(1) >= 6))
    qz = q[:, 2]
    mz = (qz * Vf).sum(1) / np.maximum(Vf.sum(1), 1)
    relief = np.sqrt((((qz - mz[:, None]) ** 2) * Vf).sum(1) / np.maximum(Vf.sum(1), 1))
    return ObjectFits(np.exp(logf), var, np.exp(logs), Rm, t, quality, mirrored, sig_px, sig_d,
                      (w_rob > 0.5 * Vf).sum(1) / np.maximum(V.sum(1), 1), V.sum(1), ok, relief,
                      tilt,
                      np.where(np.isfinite(tilt_chi2), tilt_chi2, 0.0))


# The compiled path: ``_fit_kernel`` and its helpers (compiled into it, see
# compiled.kernel_helper) do what fit_objects' numpy code does, object by object over the first
# n[k] (the valid) pixels of the padded arrays.


@kernel_helper
def _orthogonal_fit_one(P, Y, W, n, proper):
    """One object's ``_orthogonal_fit`` over its first n pixels: (s, Q, t, quality, mirrored)."""
    wsum = 0.0
    for i in range(n):
        wsum += W[i]
    wsum = max(wsum, 1e-300)
    mp = np.zeros(3)
    my = np.zeros(3)
    for i in range(n):
        wn = W[i] / wsum
        for c in range(3):
            mp[c] += wn * P[i, c]
            my[c] += wn * Y[i, c]
    cov = np.zeros((3, 3))
    vp = 0.0
    vy = 0.0
    pc = np.empty(3)
    yc = np.empty(3)
    for i in range(n):
        wn = W[i] / wsum
        for c in range(3):
            pc[c] = P[i, c] - mp[c]
            yc[c] = Y[i, c] - my[c]
        for a in range(3):
            ya = yc[a] * wn
            for b in range(3):
                cov[a, b] += ya * pc[b]
        vp += wn * (pc[0] * pc[0] + pc[1] * pc[1] + pc[2] * pc[2])
        vy += wn * (yc[0] * yc[0] + yc[1] * yc[1] + yc[2] * yc[2])
    if not np.all(np.isfinite(cov)):  # numba's SVD refuses non-finite input
        return np.nan, np.full((3, 3), np.nan), np.full(3, np.nan), np.nan, False
    U, S, Vt = np.linalg.svd(cov)
    Q = U @ Vt
    det = (Q[0, 0] * (Q[1, 1] * Q[2, 2] - Q[1, 2] * Q[2, 1])
           - Q[0, 1] * (Q[1, 0] * Q[2, 2] - Q[1, 2] * Q[2, 0])
           + Q[0, 2] * (Q[1, 0] * Q[2, 1] - Q[1, 1] * Q[2, 0]))
    total = S[0] + S[1] + S[2]
    proper_total = total - (2 * S[2] if det < 0 else 0.0)
    denom = max(vp * vy, 1e-300)
    quality = total ** 2 / denom
    quality_proper = max(proper_total, 0.0) ** 2 / denom
    mirrored = det < 0 and quality - quality_proper > 0.2
    if proper:
        fix = 1.0 if mirrored else np.sign(det)
        for a in range(3):
            U[a, 2] *= fix
        Q = U @ Vt
        if not mirrored:
            total = proper_total
    s = total / max(vp, 1e-300) if vp > 0 else 0.0
    t = np.empty(3)
    for a in range(3):
        t[a] = my[a] - s * (Q[a, 0] * mp[0] + Q[a, 1] * mp[1] + Q[a, 2] * mp[2])
    return s, Q, t, min(max(quality, 0.0), 1.0), mirrored


@compiled.reassociating_helper
def _gram_k(J, M):
    """M = J J^T (the dot products of J's rows) for the fit's normal equations. Twice as fast
    as np.dot's BLAS call on these shapes (10 x 600: 4.4 against 8.1 us; 7 x 300: 0.9 against
    4.3 us), whose fixed cost dominates; the sums vectorised, so equal to BLAS's up to
    rounding."""
    n, m = J.shape
    for a in range(n):
        ja = J[a]
        for b in range(a, n):
            jb = J[b]
            acc = 0.0
            for i in range(m):
                acc += ja[i] * jb[i]
            M[a, b] = acc
            M[b, a] = acc


@kernel_helper
def _lu_factor(A, piv):
    """In-place LU factorisation with partial pivoting (LAPACK getrf's); False at an exactly
    zero pivot, where numpy's solve and inv raise LinAlgError."""
    n = A.shape[0]
    for j in range(n):
        p = j
        big = abs(A[j, j])
        for i in range(j + 1, n):
            if abs(A[i, j]) > big:
                big = abs(A[i, j])
                p = i
        piv[j] = p
        if p != j:
            for c in range(n):
                A[j, c], A[p, c] = A[p, c], A[j, c]
        if A[j, j] == 0.0:
            return False
        inv = 1.0 / A[j, j]
        for i in range(j + 1, n):
            A[i, j] *= inv
            lij = A[i, j]
            if lij != 0.0:
                for c in range(j + 1, n):
                    A[i, c] -= lij * A[j, c]
    return True


@kernel_helper
def _lu_solve(LU, piv, b):
    """Solve with ``_lu_factor``'s factors, in place on b."""
    n = LU.shape[0]
    for j in range(n):
        p = piv[j]
        if p != j:
            b[j], b[p] = b[p], b[j]
    for i in range(n):
        acc = b[i]
        for c in range(i):
            acc -= LU[i, c] * b[c]
        b[i] = acc
    for i in range(n - 1, -1, -1):
        acc = b[i]
        for c in range(i + 1, n):
            acc -= LU[i, c] * b[c]
        b[i] = acc / LU[i, i]


@kernel
def _fit_kernel(X, D, P, n, focal0, fix_focal, iterations, depth_tilt, proper):
    """fit_objects after the padding: the start, the Gauss-Newton iterations and the outputs.

    Iterations run over all objects in step, as the numpy loop does, so that an exactly
    singular system stops every object's iterations alike (there numpy's batched solve
    raises). Each object's normal equations come from one pass over its pixels that fills
    only the Jacobian's non-zero blocks: u and v depend on neither the tilt nor the other image
    coordinate's translation, d on neither f, w_z, t_x nor t_y.
    """
    o, m = D.shape
    k0 = 0 if fix_focal else 1
    npar = k0 + 7 + (2 if depth_tilt else 0)
    logf = np.full(o, np.log(focal0))
    logs = np.empty(o)
    Rm = np.empty((o, 3, 3))
    t = np.empty((o, 3))
    quality = np.empty(o)
    mirrored = np.zeros(o, np.bool_)
    W = np.zeros((o, m))
    Ut = np.zeros((o, m, 2))
    Y = np.empty((m, 3))
    res = np.empty(m)
    valid_res = np.empty(m)
    # The start: two orthogonal fits to the back-projection at focal0, the second with Cauchy
    # weights from the first's residuals; then the depth tilt's regressor.
    for k in range(o):
        nk = n[k]
        for i in range(nk):
            dk = D[k, i] / focal0
            Y[i, 0] = X[k, i, 0] * dk
            Y[i, 1] = X[k, i, 1] * dk
            Y[i, 2] = D[k, i]
            W[k, i] = 1.0
        for _ in range(2):
            s, Q, tk, qual, mir = _orthogonal_fit_one(P[k], Y, W[k], nk, proper)
            nv = 0
            for i in range(nk):
                acc = 0.0
                for c in range(3):
                    e = Y[i, c] - (s * (Q[c, 0] * P[k, i, 0] + Q[c, 1] * P[k, i, 1]
                                        + Q[c, 2] * P[k, i, 2]) + tk[c])
                    acc += e * e
                res[i] = np.sqrt(acc)
                if not np.isnan(res[i]):  # the median of the others, as np.median of them
                    valid_res[nv] = res[i]
                    nv += 1
            med = _median_k(valid_res, nv) if nv > 0 else 0.0
            scale = max(_CAUCHY * MAD_TO_SIGMA * med, 1e-12)
            for i in range(nk):
                W[k, i] = 1.0 / (1.0 + (res[i] / scale) ** 2)
        logs[k] = np.log(max(s, 1e-12))
        Rm[k] = Q
        t[k] = tk
        quality[k] = qual
        mirrored[k] = mir
        cnt = max(nk, 1)
        c0 = 0.0
        c1 = 0.0
        for i in range(nk):
            c0 += X[k, i, 0]
            c1 += X[k, i, 1]
        c0 /= cnt
        c1 /= cnt
        acc = 0.0
        for i in range(nk):
            acc += (X[k, i, 0] - c0) ** 2 + (X[k, i, 1] - c1) ** 2
        span = max(np.sqrt(acc / cnt), 1e-9)
        for i in range(nk):
            Ut[k, i, 0] = (X[k, i, 0] - c0) / span
            Ut[k, i, 1] = (X[k, i, 1] - c1) / span
    tilt = np.zeros((o, 2))
    sig_px = np.ones(o)
    sig_d = np.full(o, 1e-3)
    H = np.zeros((o, npar, npar))
    g = np.zeros((o, npar))
    step = np.empty((o, npar))
    A = np.empty((npar, npar))
    piv = np.empty(npar, np.int64)
    r = np.empty((m, 3))
    pix = np.empty((3, m))  # per pixel: 1 / z and the row scales su, sd
    lam = 1e-6
    # The Jacobian's non-zero entries in two dense blocks: the u and v rows (the 2n columns of
    # Juv) in the parameters [log f], log s, w (3), t (3) (u's t_y and v's t_x are zero), the d
    # rows (Jd) in log s, w_x, w_y, t_z, [tilt (2)]; J^T W J is their two small products (BLAS),
    # added into H at these parameters' places.
    nuv = k0 + 7  # Juv's rows are the parameters 0 .. nuv - 1
    nd = 6 if depth_tilt else 4
    idd = np.array([k0, k0 + 1, k0 + 2, k0 + 6, k0 + 7, k0 + 8])
    buf_uv = np.empty(9 * 2 * m)
    buf_d = np.empty(7 * m)
    Muv = np.empty((nuv + 1, nuv + 1))
    Md = np.empty((nd + 1, nd + 1))
    for it in range(iterations):
        last = it == iterations - 1
        for k in range(o):
            nk = n[k]
            f = np.exp(logf[k])
            sc = np.exp(logs[k])
            a00, a01, a02 = Rm[k, 0, 0] * sc, Rm[k, 0, 1] * sc, Rm[k, 0, 2] * sc
            a10, a11, a12 = Rm[k, 1, 0] * sc, Rm[k, 1, 1] * sc, Rm[k, 1, 2] * sc
            a20, a21, a22 = Rm[k, 2, 0] * sc, Rm[k, 2, 1] * sc, Rm[k, 2, 2] * sc
            tx, ty, tz = t[k, 0], t[k, 1], t[k, 2]
            g0, g1 = tilt[k, 0], tilt[k, 1]
            # Residuals, and the noise levels from them with the previous robust weights.
            ss0 = 0.0
            ss1 = 0.0
            ss2 = 0.0
            wsum = 0.0
            for i in range(nk):
                p0, p1, p2 = P[k, i, 0], P[k, i, 1], P[k, i, 2]
                q0 = a00 * p0 + a01 * p1 + a02 * p2
                q1 = a10 * p0 + a11 * p1 + a12 * p2
                zc = a20 * p0 + a21 * p1 + a22 * p2 + tz
                z = zc if abs(zc) > 1e-9 else 1e-9
                iz = 1.0 / z
                pix[0, i] = iz
                fiz = f * iz
                gain = 1.0 + (Ut[k, i, 0] * g0 + Ut[k, i, 1] * g1)
                r0 = X[k, i, 0] - (q0 + tx) * fiz
                r1 = X[k, i, 1] - (q1 + ty) * fiz
                r2 = D[k, i] - zc * gain
                r[i, 0] = r0
                r[i, 1] = r1
                r[i, 2] = r2
                w = W[k, i]
                ss0 += r0 * r0 * w
                ss1 += r1 * r1 * w
                ss2 += r2 * r2 * w
                wsum += w
            wsum = max(wsum, 1e-300)
            spx = np.sqrt(max((ss0 + ss1) / (2 * wsum), (1e-6) ** 2))
            sdp = np.sqrt(max(ss2 / wsum, (1e-7 * tz) ** 2))
            sig_px[k] = spx
            sig_d[k] = sdp
            e2u = 0.5 / _CAUCHY ** 2 / spx ** 2
            e2d = 1.0 / _CAUCHY ** 2 / sdp ** 2
            if last:
                for i in range(nk):
                    W[k, i] = 1.0 / (1.0 + (e2u * r[i, 0] ** 2 + e2u * r[i, 1] ** 2
                                            + e2d * r[i, 2] ** 2))
                continue
            # The new weights, and the normal equations with each row scaled by the square root
            # of its weight w / sigma^2 (see the numpy loop for the Jacobian's entries). The
            # scaled residuals are the blocks' last rows: one product gives J^T W J and J^T W r.
            Juv = buf_uv[:(nuv + 1) * 2 * nk].reshape((nuv + 1, 2 * nk))
            Jd = buf_d[:(nd + 1) * nk].reshape((nd + 1, nk))
            c = k0  # log s
            isp = 1.0 / spx
            isd = 1.0 / sdp
            # The new weights and the rows' scales first, in a loop of their own: the divisions
            # and square roots of many pixels then overlap.
            for i in range(nk):
                w = 1.0 / (1.0 + (e2u * r[i, 0] ** 2 + e2u * r[i, 1] ** 2 + e2d * r[i, 2] ** 2))
                W[k, i] = w
                sw = np.sqrt(w)
                pix[1, i] = sw * isp
                pix[2, i] = sw * isd
            for i in range(nk):
                p0, p1, p2 = P[k, i, 0], P[k, i, 1], P[k, i, 2]
                q0 = a00 * p0 + a01 * p1 + a02 * p2
                q1 = a10 * p0 + a11 * p1 + a12 * p2
                q2 = a20 * p0 + a21 * p1 + a22 * p2
                zc = q2 + tz
                z = zc if abs(zc) > 1e-9 else 1e-9
                iz = pix[0, i]
                fiz = f * iz
                uh = (q0 + tx) * fiz
                vh = (q1 + ty) * fiz
                gain = 1.0 + (Ut[k, i, 0] * g0 + Ut[k, i, 1] * g1)
                su = pix[1, i]
                sd = pix[2, i]
                a = fiz * su
                aq0, aq1, aq2 = q0 * a, q1 * a, q2 * a
                izs = iz * su
                uz = uh * izs
                vz = vh * izs
                gs = gain * sd
                v = nk + i
                if not fix_focal:
                    Juv[0, i] = uh * su
                    Juv[0, v] = vh * su
                Juv[c, i] = aq0 - uz * q2  # log s
                Juv[c, v] = aq1 - vz * q2
                Juv[c + 1, i] = -(uz * q1)  # w
                Juv[c + 1, v] = -(vz * q1) - aq2
                Juv[c + 2, i] = uz * q0 + aq2
                Juv[c + 2, v] = vz * q0
                Juv[c + 3, i] = -aq1
                Juv[c + 3, v] = aq0
                Juv[c + 4, i] = a  # t
                Juv[c + 4, v] = 0.0
                Juv[c + 5, i] = 0.0
                Juv[c + 5, v] = a
                Juv[c + 6, i] = -uz
                Juv[c + 6, v] = -vz
                Jd[0, i] = q2 * gs
                Jd[1, i] = q1 * gs
                Jd[2, i] = -(q0 * gs)
                Jd[3, i] = gs
                if depth_tilt:
                    zs = z * sd
                    Jd[4, i] = Ut[k, i, 0] * zs
                    Jd[5, i] = Ut[k, i, 1] * zs
                Juv[nuv, i] = r[i, 0] * su
                Juv[nuv, v] = r[i, 1] * su
                Jd[nd, i] = r[i, 2] * sd
            _gram_k(Juv, Muv)
            _gram_k(Jd, Md)
            Hk = H[k]
            gk = g[k]
            Hk[:] = 0.0
            gk[:] = 0.0
            Hk[:nuv, :nuv] = Muv[:nuv, :nuv]
            gk[:nuv] = Muv[nuv, :nuv]
            for x in range(nd):
                gk[idd[x]] += Md[nd, x]
                for y in range(nd):
                    Hk[idd[x], idd[y]] += Md[x, y]
        if last:
            break
        # The damped steps of all objects, then the updates (none if a system is singular).
        singular = False
        for k in range(o):
            A[:] = H[k]
            for x in range(npar):
                A[x, x] += lam * max(H[k, x, x], 1e-12)
            if not _lu_factor(A, piv):
                singular = True
                break
            step[k] = g[k]
            _lu_solve(A, piv, step[k])
        if singular:
            break
        for k in range(o):
            sk = step[k]
            for x in range(npar):
                if not np.isfinite(sk[x]):
                    sk[x] = 0.0
            if not fix_focal:
                logf[k] += min(max(sk[0], -0.3), 0.3)
            logs[k] += min(max(sk[k0], -0.3), 0.3)
            w0 = min(max(sk[k0 + 1], -0.5), 0.5)
            w1 = min(max(sk[k0 + 2], -0.5), 0.5)
            w2 = min(max(sk[k0 + 3], -0.5), 0.5)
            Rm[k] = _rodrigues_one(w0, w1, w2) @ Rm[k]
            t[k, 0] += sk[k0 + 4]
            t[k, 1] += sk[k0 + 5]
            t[k, 2] += sk[k0 + 6]
            if depth_tilt:
                tilt[k, 0] += min(max(sk[k0 + 7], -0.05), 0.05)
                tilt[k, 1] += min(max(sk[k0 + 8], -0.05), 0.05)
    # Outputs: the covariance from the last system (numpy's inv raises, and the variances are
    # all infinite, if any object's is exactly singular), the tilt's chi-square, the inlier
    # count and the model's relief.
    var = np.full(o, np.inf)
    tilt_chi2 = np.zeros(o)
    cov_ok = True
    for k in range(o):
        A[:] = H[k]
        if not _lu_factor(A, piv):
            cov_ok = False
            break
    col = np.empty(npar)
    ct = np.empty((2, 2))
    for k in range(o):
        if not cov_ok:
            break
        A[:] = H[k]
        _lu_factor(A, piv)
        if not fix_focal:
            col[:] = 0.0
            col[0] = 1.0
            _lu_solve(A, piv, col)
            if np.isfinite(col[0]) and col[0] > 0:
                var[k] = col[0]
        if depth_tilt:
            for x in range(2):
                col[:] = 0.0
                col[npar - 2 + x] = 1.0
                _lu_solve(A, piv, col)
                ct[0, x] = col[npar - 2]
                ct[1, x] = col[npar - 1]
            if np.all(np.isfinite(ct)):
                pc = np.linalg.pinv(ct)
                chi2 = 0.0
                for x in range(2):
                    for y in range(2):
                        chi2 += tilt[k, x] * pc[x, y] * tilt[k, y]
                if np.isfinite(chi2):
                    tilt_chi2[k] = chi2
    inliers = np.zeros(o, np.int64)
    relief = np.zeros(o)
    for k in range(o):
        nk = n[k]
        cnt = max(nk, 1)
        sc = np.exp(logs[k])
        a20, a21, a22 = Rm[k, 2, 0] * sc, Rm[k, 2, 1] * sc, Rm[k, 2, 2] * sc
        mz = 0.0
        for i in range(nk):
            mz += a20 * P[k, i, 0] + a21 * P[k, i, 1] + a22 * P[k, i, 2]
            if W[k, i] > 0.5:
                inliers[k] += 1
        mz /= cnt
        acc = 0.0
        for i in range(nk):
            acc += (a20 * P[k, i, 0] + a21 * P[k, i, 1] + a22 * P[k, i, 2] - mz) ** 2
        relief[k] = np.sqrt(acc / cnt)
    return (logf, var, logs, Rm, t, quality, mirrored, sig_px, sig_d, inliers, relief, tilt,
            tilt_chi2)


@kernel_helper
def _rodrigues_one(w0, w1, w2):
    """``_rodrigues`` of one rotation vector."""
    th = np.sqrt(w0 * w0 + w1 * w1 + w2 * w2)
    d = th if th > 0 else 1.0
    k = np.array([w0 / d, w1 / d, w2 / d])
    s = np.sin(th)
    c = np.cos(th)
    R = np.empty((3, 3))
    for a in range(3):
        for b in range(3):
            R[a, b] = (k[a] * (1.0 - c)) * k[b]
        R[a, a] += c
    R[0, 1] -= k[2] * s
    R[0, 2] += k[1] * s
    R[1, 0] += k[2] * s
    R[1, 2] -= k[0] * s
    R[2, 0] -= k[1] * s
    R[2, 1] += k[0] * s
    return R
