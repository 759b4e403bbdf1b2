"""Least-squares refinement of the focal length over all inlier pixels of all objects.

For a focal length f the back-projected points are X(f) = diag(1/f, 1/f, 1) Y with
Y = [d u, d v, d]. The best similarity from X(f) to the NOCS points leaves a residual in NOCS
units (a fixed, focal-independent space, unlike metres, whose lateral extent shrinks with f):

    RSS_o(f) = n_o * (var_p - nuc(Cov(p, X(f)))^2 / var_X(f))

with ``nuc`` the sign-corrected nuclear norm (Umeyama). Everything needed is seven numbers per
object (sufficient statistics), so a window of many frames refines cheaply. The focal length
minimises sum_o n_o log RSS_o(f): the profile likelihood with an unknown noise level per
object, which weights each object by how well it fits. The depth-noise bias of Cov(Y, Y)
(errors in variables) is subtracted using the per-pixel depth variance.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import minimize_scalar


@dataclass
class ObjectStats:
    """Sufficient statistics of objects for the focal profile, stacked over objects (O,).

    n: effective pixel count, cpy: (O,3,3) Cov(p, Y), cyy: (O,3,3) bias-corrected Cov(Y, Y),
    vp: (O,) total NOCS variance.
    """

    n: np.ndarray
    cpy: np.ndarray
    cyy: np.ndarray
    vp: np.ndarray

    @staticmethod
    def empty() -> "ObjectStats":
        return ObjectStats(np.zeros(0), np.zeros((0, 3, 3)), np.zeros((0, 3, 3)), np.zeros(0))

    @staticmethod
    def concatenate(items) -> "ObjectStats":
        items = [s for s in items if len(s.n)]
        if not items:
            return ObjectStats.empty()
        return ObjectStats(*(np.concatenate([getattr(s, k) for s in items])
                             for k in ("n", "cpy", "cyy", "vp")))

    def __len__(self) -> int:
        return len(self.n)


def object_stats(x: np.ndarray, d: np.ndarray, p: np.ndarray, var_d=None) -> ObjectStats:
    """Statistics of one object's pixels: x (N,2) px from the principal point, d (N,) metres,
    p (N,3) NOCS, var_d optional per-pixel depth noise variance (m^2) for the bias correction."""
    y = np.column_stack([d * x[:, 0], d * x[:, 1], d])
    n = len(d)
    ones = np.full(n, 1.0 / n)
    yc = y - ones @ y  # BLAS means: .mean(0) on (n, 3) is slow
    pc = p - ones @ p
    cpy = pc.T @ yc / n
    cyy = yc.T @ yc / n
    if var_d is not None:
        r = np.column_stack([x, np.ones(n)])
        bias = (r * np.broadcast_to(var_d, (n,))[:, None]).T @ r / n
        cyy = cyy - _limit_bias(bias, cyy)
    vp = float(np.einsum("ij,ij->", pc, pc)) / n
    return ObjectStats(np.array([float(n)]), cpy[None], cyy[None], np.array([vp]))


def _limit_bias(bias: np.ndarray, cyy: np.ndarray, max_share: float = 0.5) -> np.ndarray:
    """Scale the bias matrix down so that it removes at most ``max_share`` of any variance."""
    ratio = np.max(np.diag(bias) / np.maximum(np.diag(cyy), 1e-300))
    return bias * min(1.0, max_share / ratio) if ratio > 0 else bias


def profile_cost(stats: ObjectStats, focal) -> np.ndarray:
    """sum_o n_o log RSS_o(f) for each focal in ``focal`` (G,). Lower is better."""
    f = np.atleast_1d(np.asarray(focal, dtype=np.float64))
    inv = 1.0 / f
    dscale = np.stack([inv, inv, np.ones_like(f)], axis=1)  # (G,3)
    # Cov(p, X) = Cov(p, Y) D and var_X = tr(D Cyy D), for every (focal, object).
    cpx = stats.cpy[None, :, :, :] * dscale[:, None, None, :]
    diag = np.diagonal(stats.cyy, axis1=1, axis2=2)  # (O,3)
    var_x = (dscale[:, None, :] ** 2 * diag[None]).sum(-1)  # (G,O)
    # Singular values from the eigenvalues of M^T M (2-3x faster than a batched SVD of 3x3s),
    # ascending; the smallest takes the sign of det M (Umeyama's reflection fix).
    ev = np.linalg.eigvalsh(np.swapaxes(cpx, -1, -2) @ cpx)
    sv = np.sqrt(np.maximum(ev, 0.0))
    nuc = sv[..., 2] + sv[..., 1] + np.where(_det3(cpx) < 0, -1.0, 1.0) * sv[..., 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        rss = stats.vp[None] - nuc ** 2 / var_x
    floor = 1e-14 * stats.vp[None]
    rss = np.where(np.isfinite(rss), np.maximum(rss, floor), np.inf)
    return (stats.n[None] * np.log(rss)).sum(-1)


def _det3(m: np.ndarray) -> np.ndarray:
    """Determinants of a stack of 3x3 matrices, written out (cheaper than LU for 3x3)."""
    return (m[..., 0, 0] * (m[..., 1, 1] * m[..., 2, 2] - m[..., 1, 2] * m[..., 2, 1])
            - m[..., 0, 1] * (m[..., 1, 0] * m[..., 2, 2] - m[..., 1, 2] * m[..., 2, 0])
            + m[..., 0, 2] * (m[..., 1, 0] * m[..., 2, 1] - m[..., 1, 1] * m[..., 2, 0]))


def refine_focal(stats: ObjectStats, focal0: float, search: float = 0.3, grid: int = 25, tol: float = 1e-8):
    """Minimise :func:`profile_cost` over log f within focal0 * exp(+-search).

    A vectorised grid finds the basin (the cost can have a second minimum far away), Brent's
    bounded search polishes it to ``tol`` in log f.
    Returns (focal, std_rel): std_rel is the relative standard error from the cost's curvature
    (optimistic when pixel noise is correlated), or None.
    """
    if len(stats) == 0 or not np.isfinite(focal0) or focal0 <= 0:
        return None, None
    g = np.linspace(np.log(focal0) - search, np.log(focal0) + search, grid)
    cost = profile_cost(stats, np.exp(g))
    if not np.isfinite(cost).any():
        return None, None
    i = int(np.argmin(np.where(np.isfinite(cost), cost, np.inf)))
    lo, hi = g[max(i - 1, 0)], g[min(i + 1, grid - 1)]
    res = minimize_scalar(lambda c: float(profile_cost(stats, np.exp(c))[0]), bounds=(lo, hi), method="bounded",
                          options={"xatol": tol})
    c = float(res.x) if res.fun <= cost[i] else float(g[i])
    h = 1e-4
    fm, f0, fp = profile_cost(stats, np.exp([c - h, c, c + h]))
    curv = (fm - 2 * f0 + fp) / h ** 2
    std = float(np.sqrt(2.0 / curv)) if np.isfinite(curv) and curv > 0 else None
    return float(np.exp(c)), std
