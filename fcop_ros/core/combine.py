"""Random-effects combination of per-object focal estimates (in log f).

Each object o gives log f_o with a within-object variance v_o (its fit's curvature). Objects
also err systematically (the category prior's shape is not this object's, the depth network
flattens it, a smooth depth error tilts it): a between-object variance tau^2 that no single
object's residuals show, but their disagreement does. tau^2 is estimated from that disagreement
(DerSimonian-Laird) and shrunk towards a prior tau0^2 worth ``nu0`` objects, so one or two
objects still get an honest spread. The combined estimate weights each object by
1 / (v_o + tau^2); its variance is 1 / sum of those weights. Objects further than ``reject``
standard deviations from the others are dropped first (a wrong category, a garbage mask, a
depth error the fit could not absorb).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Combined:
    """mean: combined log f; var: its variance; tau2: between-object variance used; used: (n,)
    bool, the objects kept."""

    mean: float
    var: float
    tau2: float
    used: np.ndarray


def random_effects(y, v, tau0: float, nu0: float = 2.0, reject: float = 3.0) -> Combined | None:
    """Combine estimates y (n,) with within variances v (n,); None when nothing is finite.

    With three or more objects, each is first tested against the combination of the others
    (a leave-one-out prediction interval of ``reject`` standard deviations): an outlier can
    then not hide by inflating tau^2. The worst offender goes, and the test is repeated."""
    y = np.asarray(y, dtype=np.float64)
    v = np.asarray(v, dtype=np.float64)
    used = np.isfinite(y) & np.isfinite(v) & (v > 0)
    while used.sum() >= 3:
        idx = np.flatnonzero(used)
        z = np.zeros(idx.size)
        for n, i in enumerate(idx):
            rest = _combine(y[idx[idx != i]], v[idx[idx != i]], tau0, nu0)
            z[n] = abs(y[i] - rest.mean) / np.sqrt(v[i] + rest.tau2 + rest.var)
        if z.max() <= reject:
            break
        used[idx[int(np.argmax(z))]] = False
    if not used.any():
        return None
    res = _combine(y[used], v[used], tau0, nu0)
    return Combined(res.mean, res.var, res.tau2, used)


def _combine(y, v, tau0, nu0):
    k = y.size
    w = 1.0 / v
    mean_fe = float(np.sum(w * y) / w.sum())
    tau2_dl = 0.0
    if k > 1:
        q = float(np.sum(w * (y - mean_fe) ** 2))
        c = w.sum() - np.sum(w * w) / w.sum()
        tau2_dl = max(0.0, (q - (k - 1)) / c) if c > 0 else 0.0
    tau2 = (nu0 * tau0 ** 2 + (k - 1) * tau2_dl) / (nu0 + k - 1)
    ws = 1.0 / (v + tau2)
    mean = float(np.sum(ws * y) / ws.sum())
    return Combined(mean, float(1.0 / ws.sum()), float(tau2), np.ones(k, dtype=bool))
