"""Combination of per-object focal estimates (in log f) into the frame's.

Each object o gives log f_o with the variance n_o of its fit's curvature (pixel noise, the
information its pixels carry) and a total variance v_o >= n_o that adds the systematic errors
its residuals cannot show (:mod:`.error_model`). Objects also disagree beyond both (the
category prior's shape is not this object's, the depth network flattens it, a smooth depth
error tilts it): a between-object variance tau^2 that no single object's residuals show, but
their disagreement does. tau^2 is estimated from that disagreement (DerSimonian-Laird) and
shrunk towards a prior tau0^2 worth ``nu0`` objects, so one or two objects still get an honest
spread.

The estimate weights each object by 1 / n_o: within a frame the fits' noise ranks the objects'
errors better than the systematic budget does, which is sized for the variance on average, not
to tell objects apart (``bench/world_accuracy.py --parts weights``: on 300 ``predicted`` frames
of each of the three error models, weights 1 / std_rel^2 gave the higher median error; the
weights this replaced, 1 / (v_o + tau^2), compared on the same frames in docs/BENCHMARKS.md).
The variance is that of this weighted mean under the full model, sum(w^2 (v + tau^2)) /
sum(w)^2. Objects further than ``reject`` standard deviations from the others are dropped first
(a wrong category, a garbage mask, a depth error the fit could not absorb).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Combined:
    """mean: combined log f; var: its variance; noise: the part of var that the fits' noise
    makes; tau2: between-object variance used; used: (n,) bool, the objects kept; prior: the
    part of var that the prior spread tau0^2 makes (all of tau2's part for one object, little
    for many)."""

    mean: float
    var: float
    noise: float
    tau2: float
    used: np.ndarray
    prior: float = 0.0


def combine_objects(y, v, noise, tau0: float, nu0: float = 2.0,
                    reject: float = 3.0) -> Combined | None:
    """Combine estimates y (n,) with total variances v (n,) and noise variances noise (n,)
    (clipped to v); None when nothing is finite.

    With three or more objects, each is first tested against the combination of the others
    (a leave-one-out prediction interval of ``reject`` standard deviations): an outlier can
    then not hide by inflating tau^2. The worst offender goes, and the test is repeated."""
    y = np.asarray(y, dtype=np.float64)
    v = np.asarray(v, dtype=np.float64)
    noise = np.minimum(np.asarray(noise, dtype=np.float64), v)
    used = np.isfinite(y) & np.isfinite(v) & (v > 0) & np.isfinite(noise) & (noise > 0)
    # A frame has a handful of objects: Python floats, summed in numpy's order (``_sum``),
    # give numpy's numbers at a fraction of the cost of numpy calls on arrays of five.
    yl, vl, nl = y.tolist(), v.tolist(), noise.tolist()
    while used.sum() >= 3:
        idx = np.flatnonzero(used).tolist()
        z = np.zeros(len(idx))
        for n, i in enumerate(idx):
            rest = [j for j in idx if j != i]
            mean, var, _, tau2, _ = _combine([yl[j] for j in rest], [vl[j] for j in rest],
                                             [nl[j] for j in rest], tau0, nu0)
            z[n] = abs(yl[i] - mean) / math.sqrt(vl[i] + tau2 + var)
        if z.max() <= reject:
            break
        used[idx[int(np.argmax(z))]] = False
    if not used.any():
        return None
    keep = np.flatnonzero(used).tolist()
    mean, var, var_noise, tau2, prior = _combine(
        [yl[j] for j in keep], [vl[j] for j in keep], [nl[j] for j in keep], tau0, nu0)
    return Combined(mean, var, var_noise, tau2, used, min(prior, var - var_noise))


def _combine(y: list, v: list, noise: list, tau0, nu0):
    """(mean, var, noise var, tau2, prior var) of the estimates y with total variances v and
    noise variances ``noise`` (lists of floats); prior var: the part of var that the prior's
    share of tau2 makes, through the same weights as every object's variance."""
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
    share = nu0 * tau0 ** 2 / (nu0 + k - 1)  # the prior's part of tau2
    wn = [1.0 / ni for ni in noise]
    swn = _sum(wn)
    mean = _sum([wi * yi for wi, yi in zip(wn, y)]) / swn
    var = _sum([wi * wi * (vi + tau2) for wi, vi in zip(wn, v)]) / (swn * swn)
    prior = _sum([wi * wi for wi in wn]) * share / swn ** 2
    return mean, var, 1.0 / swn, float(tau2), prior


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
