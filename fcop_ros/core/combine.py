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

import math
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
    # A frame has a handful of objects: Python floats, summed in numpy's order (``_sum``),
    # give numpy's numbers at a fraction of the cost of numpy calls on arrays of five.
    yl, vl = y.tolist(), v.tolist()
    while used.sum() >= 3:
        idx = np.flatnonzero(used).tolist()
        z = np.zeros(len(idx))
        for n, i in enumerate(idx):
            rest = [j for j in idx if j != i]
            mean, var, tau2 = _combine([yl[j] for j in rest], [vl[j] for j in rest], tau0, nu0)
            z[n] = abs(yl[i] - mean) / math.sqrt(vl[i] + tau2 + var)
        if z.max() <= reject:
            break
        used[idx[int(np.argmax(z))]] = False
    if not used.any():
        return None
    keep = np.flatnonzero(used).tolist()
    mean, var, tau2 = _combine([yl[j] for j in keep], [vl[j] for j in keep], tau0, nu0)
    return Combined(mean, var, tau2, used)


def _combine(y: list, v: list, tau0, nu0):
    """(mean, var, tau2) of the estimates y with within variances v (lists of floats)."""
    k = len(y)
    w = [1.0 / vi for vi in v]
    sw = _sum(w)
    mean_fe = _sum([wi * yi for wi, yi in zip(w, y)]) / sw
    tau2_dl = 0.0
    if k > 1:
        q = _sum([wi * ((yi - mean_fe) * (yi - mean_fe)) for wi, yi in zip(w, y)])
        c = sw - _sum([wi * wi for wi in w]) / sw
        tau2_dl = max(0.0, (q - (k - 1)) / c) if c > 0 else 0.0
    tau2 = (nu0 * tau0 ** 2 + (k - 1) * tau2_dl) / (nu0 + k - 1)
    ws = [1.0 / (vi + tau2) for vi in v]
    sws = _sum(ws)
    return _sum([wi * yi for wi, yi in zip(ws, y)]) / sws, 1.0 / sws, float(tau2)


def _sum(a: list) -> float:
    """``float(np.sum(a))`` to the bit: numpy's pairwise summation (eight accumulators in
    blocks of up to 128, halves above), in Python for short lists."""
    n = len(a)
    if n < 8:
        res = 0.0
        for x in a:
            res += x
        return res
    if n <= 128:
        r = a[:8]
        i = 8
        while i < n - n % 8:
            for j in range(8):
                r[j] += a[i + j]
            i += 8
        res = ((r[0] + r[1]) + (r[2] + r[3])) + ((r[4] + r[5]) + (r[6] + r[7]))
        for x in a[i:]:
            res += x
        return res
    n2 = n // 2
    n2 -= n2 % 8
    return _sum(a[:n2]) + _sum(a[n2:])
