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
little Levenberg damping and Cauchy weights against outliers.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

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
        k_n = len(pick)
        X[k, :k_n], D[k, :k_n], P[k, :k_n] = inst.x[pick], inst.d[pick], inst.p[pick] - 0.5
        V[k, :len(pick)] = True
    return X, D, P, V


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
