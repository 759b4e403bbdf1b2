"""Interval stabbing: globally optimal 1D consensus maximisation in O(n log n).

Given closed intervals [lo_i, hi_i] with positive weights, find a point that lies in intervals
of the largest total weight. Tie rule: intervals are closed, so intervals that only touch
(hi_a == lo_b) overlap and are stabbed together by the touching point.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class StabbingResult:
    """Outcome of :func:`interval_stabbing`.

    point: a point of maximal consensus (middle of the maximal-depth region), or None.
    count: total weight of the intervals containing ``point`` (their number when unweighted).
    region: (start, end) of the maximal-depth region that contains ``point``.
    inliers: (n,) bool mask of the intervals containing ``point``.
    """

    point: float | None
    count: float
    region: tuple[float, float] | None
    inliers: np.ndarray


def interval_stabbing(lo, hi, weights=None) -> StabbingResult:
    """Stab closed intervals [lo, hi] at the point of largest total weight.

    Args:
        lo, hi: (n,) interval ends; intervals with lo > hi or non-finite ends are ignored.
        weights: optional (n,) non-negative weights (default 1); zero-weight intervals are
            ignored when choosing the point but still reported as inliers if stabbed.

    Among regions of equal maximal weight the leftmost wins. Sorting the 2n end points is the
    only super-linear step.
    """
    lo = np.asarray(lo, dtype=np.float64).ravel()
    hi = np.asarray(hi, dtype=np.float64).ravel()
    if lo.shape != hi.shape:
        raise ValueError(f"interval_stabbing: lo and hi differ in shape {lo.shape} vs {hi.shape}")
    n = lo.size
    w = np.ones(n) if weights is None else np.asarray(weights, dtype=np.float64).ravel()
    if w.shape != lo.shape:
        raise ValueError("interval_stabbing: weights must have one entry per interval")
    use = np.isfinite(lo) & np.isfinite(hi) & (lo <= hi) & np.isfinite(w) & (w > 0)
    if not use.any():
        return StabbingResult(None, 0.0, None, np.zeros(n, dtype=bool))
    # Processing the starts in sorted order, the depth just after the i-th start x is
    # W(first i+1 starts) - W(hi < x) (closed intervals: an end at x still counts), and the
    # maximum is attained at a start. Sorts and one binary search: O(n log n). With ties among
    # the starts the cumulative weight grows along them, so the first maximum is the last of
    # the tied starts, as it must be.
    lo_u, hi_u = lo[use], hi[use]
    if weights is None:
        lo_s, hi_s = np.sort(lo_u), np.sort(hi_u)
        depth = np.arange(1, lo_s.size + 1) - np.searchsorted(hi_s, lo_s, side="left")
    else:
        w_u = w[use]
        order_lo, order_hi = np.argsort(lo_u), np.argsort(hi_u)
        lo_s, hi_s = lo_u[order_lo], hi_u[order_hi]
        cw_hi = np.concatenate([[0.0], np.cumsum(w_u[order_hi])])
        depth = np.cumsum(w_u[order_lo]) - cw_hi[np.searchsorted(hi_s, lo_s, side="left")]
    best = int(np.argmax(depth))  # first maximum in sorted order: the leftmost region
    start = lo_s[best]
    end = hi_s[np.searchsorted(hi_s, start, side="left")]  # the first end at or after the start
    point = 0.5 * (start + end)
    inliers = (lo <= point) & (point <= hi) & np.isfinite(lo) & np.isfinite(hi)
    count = float(w[inliers & use].sum())
    return StabbingResult(float(point), count, (float(start), float(end)), inliers)


def focal_intervals(focal, bound: float, mode: str = "relative"):
    """Turn focal votes (pixels) into stabbing intervals.

    mode "relative": intervals in log f, [log f - log(1+bound), log f + log(1+bound)], so the
    bound (a fraction, e.g. 0.03) means the same at every focal length.
    mode "absolute": the paper's bound in pixels, [f - bound, f + bound].
    Returns (lo, hi, to_focal) where to_focal maps a stabbing point back to pixels.
    """
    focal = np.asarray(focal, dtype=np.float64)
    if mode == "relative":
        if not bound > 0:
            raise ValueError("relative noise bound must be > 0")
        with np.errstate(divide="ignore", invalid="ignore"):
            c = np.log(focal)
        r = np.log1p(bound)
        return c - r, c + r, np.exp
    if mode == "absolute":
        if not bound > 0:
            raise ValueError("absolute noise bound must be > 0 pixels")
        return focal - bound, focal + bound, lambda v: v
    raise ValueError(f"unknown noise bound mode {mode!r}; use 'relative' or 'absolute'")
