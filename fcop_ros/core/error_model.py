"""The errors that repeat in every frame: how much they move an object's fitted focal length,
and the variance of log f they add to the fit's own.

The per-object fit (:mod:`.object_fit`) weighs two kinds of evidence: where the pixels are (the
reprojection of the NOCS) and how deep they are. An error of the depth network that is the same
for every frame of an object (its relief flattened, an additive offset, a curved depth-error
field the fit's tilt cannot absorb) shows in no residual, so its effect on f is computed:
at the fit's optimum the parameters move by dtheta = H^-1 J_d^T W_d delta_d for a depth
perturbation delta_d, where H = J^T W J is the fit's normal matrix over both kinds of rows. When
the pixels pin f down (exact NOCS: a perspective-n-point problem) a depth error barely moves it;
when noisy NOCS leave f to the depths, it moves f one for one (a relief error delta gives -delta
in log f, an offset o gives o / z). The unseen-depth term is sized by that derivative, so it
follows the fit's actual lean. The NOCS side: a category prior's shape that is not this object's
errs in f about as much as it misfits the shape, a misfit told from the depth's by its part
across the pixels' rays where a second object can show what the fit's own variance misses.
"""
from __future__ import annotations

import numpy as np

from . import compiled
from .compiled import kernel
from .correspondences import _mean
from .object_fit import _CAUCHY, ObjectFits, _gram_k, _lu_factor, _lu_solve, _plain_rows

#: The depth-error patterns, in the order of :func:`depth_influence`'s columns.
PATTERNS = ("relief", "offset")


def depth_influence(instances, fits: ObjectFits, max_pixels: int = 300,
                    depth_tilt: bool = True) -> np.ndarray:
    """d log f / d(error) of every object (O, 2) for the :data:`PATTERNS`.

    relief: a relative scaling of the object's depths about their mean (unitless); offset: one
    metre added to every depth. Computed at the fitted parameters on up to ``max_pixels``
    pixels per object (every k-th), with the fit's noise levels and robust weights
    (``depth_tilt`` as the fit had it). Rows of objects whose fit is not ok are NaN.
    """
    o = len(instances)
    out = np.full((o, len(PATTERNS)), np.nan)
    if o == 0:
        return out
    m = min(max(len(i.d) for i in instances), max_pixels)
    if compiled.ENABLED:
        # Only the rows the kernel reads (every k-th, at most m per object), gathered object
        # by object: then it reads all of each object's rows, the same ones.
        cnt = np.array([min(len(i.d), m) for i in instances], dtype=np.int64)
        offsets = np.concatenate([[0], np.cumsum(cnt)])
        x, d, p = np.empty((offsets[-1], 2)), np.empty(offsets[-1]), np.empty((offsets[-1], 3))
        for k, inst in enumerate(instances):
            rows = (inst.x, inst.d, inst.p)
            if not _plain_rows(*rows):  # the one signature the kernel is compiled for
                rows = [np.ascontiguousarray(a, dtype=np.float64) for a in rows]
            _every_kth_rows_k(x, d, p, offsets[k], *rows, m)
        out = _influence_kernel(
            x, d, p, offsets, m, fits.focal, fits.scale,
            np.ascontiguousarray(fits.rotation), np.ascontiguousarray(fits.translation),
            np.ascontiguousarray(fits.tilt), fits.sigma_px, fits.sigma_depth, depth_tilt)
        out[~(fits.ok & np.all(np.isfinite(out), 1))] = np.nan
        return out
    X = np.zeros((o, 2, m))
    D = np.ones((o, m))
    P = np.zeros((o, 3, m))
    V = np.zeros((o, m))
    for k, inst in enumerate(instances):
        n = len(inst.d)
        pick = (np.arange(m) * (n - 1)) // max(m - 1, 1) if n > m else np.arange(n)
        X[k, :, : len(pick)], D[k, : len(pick)] = inst.x[pick].T, inst.d[pick]
        P[k, :, : len(pick)] = inst.p[pick].T - 0.5
        V[k, : len(pick)] = 1.0
    cnt = np.maximum(V.sum(1), 1.0)
    cen = (X * V[:, None]).sum(2) / cnt[:, None]
    Xr = X - cen[:, :, None]
    span = np.sqrt(((Xr * Xr).sum(1) * V).sum(1) / cnt)
    U = Xr / np.maximum(span, 1e-9)[:, None, None]  # (O, 2, M)

    # Predictions at the fit: q = s R (p - 0.5), X = q + t, (u, v) = f X_xy / z, d = z gain.
    q = (fits.rotation * fits.scale[:, None, None]) @ P  # (O, 3, M)
    Xc = q + fits.translation[:, :, None]
    z = np.where(np.abs(Xc[:, 2]) > 1e-9, Xc[:, 2], 1e-9)
    a = fits.focal[:, None] / z
    uv = Xc[:, :2] * a[:, None]
    uvz = uv / z[:, None]
    gain = 1.0 + (U * fits.tilt[:, :, None]).sum(1)
    r_uv = X - uv
    r_d = D - z * gain
    sp = np.maximum(fits.sigma_px, 1e-6)[:, None]
    sd = np.maximum(fits.sigma_depth, 1e-12)[:, None]
    e2 = (r_uv * r_uv).sum(1) / (2 * sp**2) + r_d**2 / sd**2
    sw = np.sqrt(V / (1.0 + e2 / _CAUCHY**2))
    su, sdw = sw / sp, sw / sd  # square roots of the rows' weights w / sigma^2

    # The Jacobian of the predictions (u, v, d) in [log f, log s, w (3), t (3), tilt (2)] as in
    # the fit, scaled by the square roots of the row weights: (O, 10, 3, M).
    npar = 10 if depth_tilt else 8
    J = np.zeros((o, npar, 3, m))
    aq = q * (a * su)[:, None]
    B = (uvz * su[:, None])[:, :, None] * q[:, None]  # (O, 2, 3, M): [uz, vz] x [qx, qy, qz]
    gq = q * (gain * sdw)[:, None]
    J[:, 0, :2] = uv * su[:, None]
    J[:, 1, :2] = aq[:, :2] - B[:, :, 2]
    J[:, 1, 2] = gq[:, 2]
    J[:, 2, :2] = -B[:, :, 1]
    J[:, 2, 1] -= aq[:, 2]
    J[:, 2, 2] = gq[:, 1]
    J[:, 3, :2] = B[:, :, 0]
    J[:, 3, 0] += aq[:, 2]
    J[:, 3, 2] = -gq[:, 0]
    J[:, 4, 0] = -aq[:, 1]
    J[:, 4, 1] = aq[:, 0]
    J[:, 5, 0] = a * su
    J[:, 6, 1] = a * su
    J[:, 7, :2] = -uvz * su[:, None]
    J[:, 7, 2] = gain * sdw
    if depth_tilt:
        J[:, 8:, 2] = U * (z * sdw)[:, None]
    Jf = J.reshape(o, npar, 3 * m)
    H = Jf @ np.swapaxes(Jf, 1, 2)
    zm = (z * V).sum(1) / cnt
    phi = np.stack([(z - zm[:, None]) * sdw, sdw], -1)  # (O, M, patterns), weighted
    G = J[:, :, 2] @ phi  # J_d^T W_d phi: (O, npar, patterns)
    with np.errstate(all="ignore"):
        try:
            dtheta = np.linalg.solve(H, G)
        except np.linalg.LinAlgError:  # an exactly singular H: NaN for that object, as compiled
            dtheta = np.full(G.shape, np.nan)
            for k in range(o):
                try:
                    dtheta[k] = np.linalg.solve(H[k], G[k])
                except np.linalg.LinAlgError:
                    pass
    out = dtheta[:, 0, :]
    out[~(fits.ok & np.all(np.isfinite(out), 1))] = np.nan
    return out


@kernel
def _every_kth_rows_k(x_out, d_out, p_out, start, x, d, p, m):
    """The rows of one object that _influence_kernel reads (up to m, every k-th as it picks
    them) written from row ``start`` of the outputs."""
    n = d.size
    for j in range(min(n, m)):
        i = j * (n - 1) // max(m - 1, 1) if n > m else j
        x_out[start + j, 0], x_out[start + j, 1] = x[i, 0], x[i, 1]
        d_out[start + j] = d[i]
        p_out[start + j, 0], p_out[start + j, 1], p_out[start + j, 2] = p[i, 0], p[i, 1], p[i, 2]


@kernel
def _influence_kernel(x, d, p, offsets, m, focal, scale, rotation, translation, tilt,
                      sigma_px, sigma_depth, depth_tilt):
    """:func:`depth_influence`'s numbers, one object at a time: the same pixels (every k-th),
    predictions, robust weights and Jacobian rows, H and J_d^T W_d phi by one Gram product of
    the weighted rows (as the fit forms its normal equations), and the fit's LU solve (NaN
    where H is exactly singular)."""
    o = offsets.size - 1
    npar = 10 if depth_tilt else 8
    out = np.full((o, 2), np.nan)
    idx = np.empty(m, np.int64)
    zs = np.empty(m)
    ws = np.empty(m)
    us = np.empty((m, 2))
    qs = np.empty((m, 3))
    piv = np.empty(npar, np.int64)
    buf = np.empty(12 * 3 * m)
    gram = np.empty(12 * 12)
    for k in range(o):
        start, n = offsets[k], offsets[k + 1] - offsets[k]
        cnt = min(n, m)
        if cnt == 0:
            continue
        for j in range(cnt):
            idx[j] = start + (j * (n - 1) // max(m - 1, 1) if n > m else j)
        cx = 0.0
        cy = 0.0
        for j in range(cnt):
            cx += x[idx[j], 0]
            cy += x[idx[j], 1]
        cx /= cnt
        cy /= cnt
        ss = 0.0
        for j in range(cnt):
            ss += (x[idx[j], 0] - cx) ** 2 + (x[idx[j], 1] - cy) ** 2
        span = max(np.sqrt(ss / cnt), 1e-9)
        f, s = focal[k], scale[k]
        sp = max(sigma_px[k], 1e-6)
        sd = max(sigma_depth[k], 1e-12)
        zsum = 0.0
        for j in range(cnt):  # predictions, weights
            i = idx[j]
            q0 = p[i, 0] - 0.5
            q1 = p[i, 1] - 0.5
            q2 = p[i, 2] - 0.5
            for r in range(3):  # q = s R (p - 0.5)
                qs[j, r] = s * (rotation[k, r, 0] * q0 + rotation[k, r, 1] * q1
                                + rotation[k, r, 2] * q2)
            xc = qs[j, 0] + translation[k, 0]
            yc = qs[j, 1] + translation[k, 1]
            zc = qs[j, 2] + translation[k, 2]
            z = zc if abs(zc) > 1e-9 else 1e-9
            us[j, 0] = (x[i, 0] - cx) / span
            us[j, 1] = (x[i, 1] - cy) / span
            gain = 1.0 + us[j, 0] * tilt[k, 0] + us[j, 1] * tilt[k, 1]
            ru = x[i, 0] - f * xc / z
            rv = x[i, 1] - f * yc / z
            rd = d[i] - z * gain
            e2 = (ru * ru + rv * rv) / (2 * sp * sp) + rd * rd / (sd * sd)
            ws[j] = 1.0 / (1.0 + e2 / _CAUCHY**2)
            zs[j] = z
            zsum += z
        zm = zsum / cnt
        # The Jacobian's rows scaled by the square roots of the rows' weights, u, v and d
        # pixels side by side, with phi's two patterns (zero on u and v) as two more rows:
        # one Gram product gives H and J_d^T W_d phi.
        J = buf[:(npar + 2) * 3 * cnt].reshape((npar + 2, 3 * cnt))
        J[:] = 0.0
        for j in range(cnt):
            qx, qy, qz = qs[j, 0], qs[j, 1], qs[j, 2]
            z = zs[j]
            a = f / z
            u = (qx + translation[k, 0]) * a
            v = (qy + translation[k, 1]) * a
            uz = u / z
            vz = v / z
            g = 1.0 + us[j, 0] * tilt[k, 0] + us[j, 1] * tilt[k, 1]
            su = np.sqrt(ws[j]) / sp
            sw = np.sqrt(ws[j]) / sd
            cu, cv, cd = j, cnt + j, 2 * cnt + j
            # Columns: log f, log s, w (3), t (3), [tilt (2)]; u has no t_y, v no t_x.
            J[0, cu], J[1, cu], J[2, cu] = u * su, (a * qx - uz * qz) * su, -uz * qy * su
            J[3, cu], J[4, cu], J[5, cu] = (a * qz + uz * qx) * su, -a * qy * su, a * su
            J[7, cu] = -uz * su
            J[0, cv], J[1, cv] = v * su, (a * qy - vz * qz) * su
            J[2, cv], J[3, cv] = (-a * qz - vz * qy) * su, vz * qx * su
            J[4, cv], J[6, cv], J[7, cv] = a * qx * su, a * su, -vz * su
            J[1, cd], J[2, cd], J[3, cd] = g * qz * sw, g * qy * sw, -g * qx * sw
            J[7, cd] = g * sw
            if npar == 10:
                J[8, cd], J[9, cd] = z * us[j, 0] * sw, z * us[j, 1] * sw
            J[npar, cd] = (z - zm) * sw
            J[npar + 1, cd] = sw
        M = gram[:(npar + 2) * (npar + 2)].reshape((npar + 2, npar + 2))
        _gram_k(J, M)
        A = M[:npar, :npar].copy()
        if not _lu_factor(A, piv):
            continue
        for col in range(2):
            b = M[:npar, npar + col].copy()
            _lu_solve(A, piv, b)
            out[k, col] = b[0]
    return out


#: An object whose fitted tilt is this many times the median of the frame's (three or more)
#: is left out of the frame's depth-field curvature: its tilt is its own (a partial view, a
#: wrong fit), as a smooth field tilts neighbouring objects alike.
WILD_TILT = 5.0


def _field_tilts(tilt, good):
    """The objects whose tilts measure the frame's depth field: ``good`` less wild ones."""
    norms = np.linalg.norm(tilt, axis=1)
    if good.sum() < 3:
        return good
    return good & ~(norms > WILD_TILT * np.median(norms[good]))


def nocs_made_share(fits: ObjectFits, spread) -> np.ndarray:
    """The share of each object's misfit (1 - quality) that its NOCS made (O,), in [0, 1].

    A depth error moves a point along its ray; a NOCS error moves it every way, two thirds of
    its misfit across the rays. The pixels' residuals at the fitted focal length are that
    across part, relative to the object's 3D variance (its scale times ``spread``, the rms
    distance of its NOCS from their centroid). A smooth depth field bends an object in a way the
    similarity cannot follow, but only along the rays.
    """
    with np.errstate(over="ignore"):  # a fit that ran away: all of its misfit is the NOCS'
        across = 2.0 * (fits.sigma_px * fits.translation[:, 2]
                        / np.maximum(fits.focal * fits.scale * spread, 1e-300)) ** 2
        return np.minimum(1.5 * across / np.maximum(1.0 - fits.quality, 1e-300), 1.0)


def object_variances(support, fits: ObjectFits, good, spread, raw_spread, relief_lean,
                     options):
    """Per object (O,): the fit's variance of log f plus the systematic terms.

    support: the objects' NOCS-calibrated correspondences (the fit's input); good: the objects
    whose fit is used (they pool the tilts); spread / raw_spread: rms distance of each object's
    calibrated / raw NOCS from their centroid; relief_lean: each object's d log f per unit of
    relief error (:func:`depth_influence`'s first column). Terms, in log f: a smooth depth-error
    field's curvature, taken as ``unseen_depth_error`` times the rms of the fitted tilts over
    the frame's objects (less any tilted WILD_TILT times their median), changes an object's
    relief by about that times z, so its log f by that times z / relief times the relief
    derivative; ``shape_error`` times the square root of the
    shape share the similarity leaves unexplained, not counting the share that the measured
    depth and NOCS noise alone would leave, nor, where two or more objects are ``good``, the
    share the depth made (:func:`nocs_made_share`). A lone object keeps that share: for exact
    NOCS under a smooth depth field the fit's variance is too small (its residuals are
    correlated, the fit counts them as independent), and with no second object to disagree
    (the frame's between-object spread, :mod:`.combine`) the depth's misfit stands for it.
    """
    field = _field_tilts(fits.tilt, good)
    curvature = options.unseen_depth_error * np.sqrt(np.mean(fits.tilt[field] ** 2))
    unseen = curvature * fits.translation[:, 2] / np.maximum(fits.relief, 1e-9)
    var = fits.var_log_focal + (unseen * relief_lean) ** 2
    # Noise shares of the 3D points' and the NOCS' variance, which lower the fit's quality even
    # for a perfect shape.
    noise_y = np.array([_mean(i.var_d) for i in support]) / np.maximum(
        fits.scale**2 * spread**2, 1e-300)
    noise_p = np.array([0.0 if s.var_p is None else 3.0 * _mean(s.var_p) for s in support])
    noise_p = noise_p / np.maximum(raw_spread**2, 1e-300)
    kept = (1.0 - np.minimum(noise_y, 0.9)) * (1.0 - np.minimum(noise_p, 0.9))
    quality = np.minimum(fits.quality / kept, 1.0)
    shape = options.shape_error**2 * (1.0 - quality)
    if good.sum() >= 2:
        shape = shape * nocs_made_share(fits, spread)
    return var + shape
