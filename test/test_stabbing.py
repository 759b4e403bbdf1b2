"""Interval stabbing against an O(n^2) brute force, with ties, duplicates and weights."""
import numpy as np
import pytest

from fcop_ros import interval_stabbing
from fcop_ros.core.stabbing import focal_intervals, stab_equal_width


def brute_force(lo, hi, w):
    """Best total weight over all candidate points (every interval end)."""
    best = 0.0
    for c in np.concatenate([lo, hi]):
        inside = (lo <= c) & (c <= hi)
        best = max(best, float(w[inside].sum()))
    return best


@pytest.mark.parametrize("weighted", [False, True])
def test_equals_brute_force_on_random_cases(weighted):
    rng = np.random.default_rng(11 if weighted else 7)
    for case in range(3000):
        n = int(rng.integers(1, 40))
        if case % 3 == 0:  # integer grid: many ties, touching ends and duplicates
            lo = rng.integers(0, 10, n).astype(float)
            hi = lo + rng.integers(0, 4, n)
        else:
            lo = rng.normal(0, 1, n)
            hi = lo + rng.exponential(0.5, n)
            dup = rng.random(n) < 0.2
            lo[dup], hi[dup] = lo[0], hi[0]
        w = rng.integers(1, 5, n).astype(float) if weighted else np.ones(n)
        res = interval_stabbing(lo, hi, w if weighted else None)
        expected = brute_force(lo, hi, w)
        assert res.count == pytest.approx(expected)
        # The returned point really stabs that weight, and the mask is exactly its intervals.
        inside = (lo <= res.point) & (res.point <= hi)
        assert (inside == res.inliers).all()
        assert w[inside].sum() == pytest.approx(expected)
        assert res.region[0] <= res.point <= res.region[1]


def test_touching_intervals_overlap():
    res = interval_stabbing([0.0, 1.0, 5.0], [1.0, 2.0, 6.0])
    assert res.count == 2 and res.point == 1.0 and res.region == (1.0, 1.0)
    assert res.inliers.tolist() == [True, True, False]


def test_leftmost_of_equal_regions_and_midpoint():
    res = interval_stabbing([0.0, 0.5, 10.0, 10.5], [1.0, 2.0, 11.0, 12.0])
    assert res.count == 2 and res.region == (0.5, 1.0) and res.point == 0.75


def test_empty_invalid_and_zero_weight():
    res = interval_stabbing([], [])
    assert res.point is None and res.count == 0 and res.inliers.shape == (0,)
    res = interval_stabbing([np.nan, 2.0, 3.0], [1.0, 1.0, np.inf])  # NaN, reversed, inf
    assert res.point is None and not res.inliers.any()
    res = interval_stabbing([0.0, 5.0], [1.0, 6.0], weights=[0.0, 1.0])
    assert res.point == 5.5 and res.count == 1.0
    with pytest.raises(ValueError):
        interval_stabbing([0.0], [1.0, 2.0])


def test_relative_bound_is_scale_free_and_absolute_is_pixels():
    votes = np.array([500.0, 510.0, 540.0, 1000.0, 1020.0, 1080.0])
    lo, hi, back = focal_intervals(votes, 0.015, "relative")
    # +-1.5% joins 500/510 and 1000/1020 alike: the same relative spread counts the same.
    assert interval_stabbing(lo[:3], hi[:3]).count == interval_stabbing(lo[3:], hi[3:]).count == 2
    lo, hi, back = focal_intervals(votes, 5.0, "absolute")
    assert (
        interval_stabbing(lo[:3], hi[:3]).count == 2
        and interval_stabbing(lo[3:], hi[3:]).count == 1
    )
    with pytest.raises(ValueError):
        focal_intervals(votes, 0.0, "relative")
    with pytest.raises(ValueError):
        focal_intervals(votes, 1.0, "bogus")


@pytest.mark.parametrize("kind", ["clustered", "ties", "uniform", "two_clusters", "non_finite"])
def test_equal_width_and_pruned_search_match_the_plain_algorithm(kind):
    """stab_equal_width (one sort of the centres) and the block-pruned search give exactly
    the result of the plain algorithm: one sort per end and a binary search for every start."""
    rng = np.random.default_rng(len(kind))
    for n in (1, 7, 3000, 60_000):
        c = {"clustered": lambda: rng.normal(6.4, 0.2, n),
             "ties": lambda: np.round(rng.normal(6.4, 0.2, n), 2),
             "uniform": lambda: rng.uniform(-3.0, 3.0, n),
             "two_clusters": lambda: np.concatenate([rng.normal(0, 1, n // 2),
                                                     rng.normal(1, 0.01, n - n // 2)]),
             "non_finite": lambda: np.where(rng.random(n) < 0.1, np.nan, rng.normal(0, 1, n)),
             }[kind]()
        for r in (0.0, 0.0488):
            lo, hi = c - r, c + r
            use = np.isfinite(lo) & np.isfinite(hi)
            lo_s, hi_s = np.sort(lo[use]), np.sort(hi[use])
            best = int(np.argmax(np.arange(1, lo_s.size + 1) - np.searchsorted(hi_s, lo_s)))
            start = lo_s[best]
            point = 0.5 * (start + hi_s[np.searchsorted(hi_s, start)])
            inliers = (lo <= point) & (point <= hi)
            for got in (interval_stabbing(lo, hi), stab_equal_width(c, r)):
                assert got.point == point and got.region[0] == start
                assert np.array_equal(got.inliers, inliers) and got.count == inliers.sum()
