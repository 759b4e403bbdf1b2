"""The minimal solver: exactness on the paper's simulation, degeneracies, no NaN leaks."""
import numpy as np
import pytest

from fcop_ros import solve_triplets
from fcop_ros.core.solver import sample_triplets
from fcop_ros.synthetic import simulate_points, simulate_triplet_batch


def _solve_batch(x, d, p):
    t = len(d)
    tri = np.arange(3 * t).reshape(t, 3)
    return solve_triplets(x.reshape(-1, 2), d.reshape(-1), p.reshape(-1, 3), tri)


def test_noise_free_stability_paper_simulation():
    """10^5 noise-free triplets (paper Sec. IV-A): median relative focal error < 1e-9,
    >= 99.99% valid."""
    rng = np.random.default_rng(2024)
    x, d, p, f_true, s_true = simulate_triplet_batch(rng, 100_000)
    f, s2, valid = _solve_batch(x, d, p)
    assert valid.mean() >= 0.9999
    rel = np.abs(f[valid] / f_true[valid] - 1)
    assert np.median(rel) < 1e-9
    assert np.percentile(rel, 99) < 1e-6
    assert np.median(np.abs(np.sqrt(s2[valid]) / s_true[valid] - 1)) < 1e-9


def test_third_row_is_pair_ik():
    """Only the (i,k) pair carries i-k information: a triplet whose (i,j) and (j,k) rows are
    identical still solves exactly, which the paper's printed matrix (row (j,k) twice) cannot."""
    rng = np.random.default_rng(1)
    trial = simulate_points(rng, 3)
    f, s2, ok = solve_triplets(trial.x, trial.d, trial.p,
                               np.array([[0, 1, 2], [2, 1, 0], [1, 0, 2]]))
    assert ok.all()
    np.testing.assert_allclose(f, trial.focal, rtol=1e-9)
    np.testing.assert_allclose(s2, trial.scale ** 2, rtol=1e-9)


def test_degenerate_triplets_are_invalid_and_finite():
    rng = np.random.default_rng(3)
    trial = simulate_points(rng, 3)
    x, d, p = trial.x.copy(), trial.d.copy(), trial.p.copy()
    cases = []
    # Equal depths: no (d_a - d_b) information, the system is homogeneous.
    cases.append((x, np.full(3, 2.0), p))
    # Repeated point: a zero row and a duplicated row, the system is singular.
    cases.append((x[[0, 0, 1]], d[[0, 0, 1]], p[[0, 0, 1]]))
    # All image points at the principal point and equal NOCS: nothing to solve.
    cases.append((np.zeros((3, 2)), d, np.zeros((3, 3))))
    # NaN and inf inputs.
    cases.append((x, np.array([np.nan, 1.0, 2.0]), p))
    cases.append((np.array([[np.inf, 0], [1, 2], [3, 4]]), d, p))
    for xx, dd, pp in cases:
        f, s2, ok = solve_triplets(xx, dd, pp, np.array([[0, 1, 2]]))
        assert not ok[0]
        assert np.isfinite(f).all() and np.isfinite(s2).all()
        assert f[0] == 0.0 and s2[0] == 0.0


def test_negative_solution_is_invalid():
    """Depth differences larger than any metric shape allows give s^2 or 1/f^2 <= 0."""
    x = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
    d = np.array([1.0, 5.0, 9.0])
    p = np.array([[0, 0, 0], [1e-3, 0, 0], [0, 1e-3, 0]], float)
    f, s2, ok = solve_triplets(x, d, p, np.array([[0, 1, 2]]))
    assert not ok[0] and f[0] == 0.0


def test_shape_errors_are_clear():
    with pytest.raises(ValueError, match="expects x"):
        solve_triplets(np.zeros((3, 3)), np.zeros(3), np.zeros((3, 3)), np.array([[0, 1, 2]]))
    with pytest.raises(ValueError, match="out of range"):
        solve_triplets(np.zeros((3, 2)), np.ones(3), np.zeros((3, 3)), np.array([[0, 1, 3]]))


def test_empty_and_sampling():
    f, s2, ok = solve_triplets(np.zeros((0, 2)), np.zeros(0), np.zeros((0, 3)),
                               np.zeros((0, 3), int))
    assert f.shape == s2.shape == ok.shape == (0,)
    rng = np.random.default_rng(0)
    tri = sample_triplets(5, 10_000, rng)
    assert tri.min() >= 0 and tri.max() <= 4
    assert (
        (tri[:, 0] != tri[:, 1]).all()
        and (tri[:, 1] != tri[:, 2]).all()
        and (tri[:, 0] != tri[:, 2]).all()
    )
    # Every ordered triplet of distinct indices occurs about equally often (5*4*3 = 60 of them).
    codes = tri[:, 0] * 25 + tri[:, 1] * 5 + tri[:, 2]
    counts = np.unique(codes, return_counts=True)[1]
    assert len(counts) == 60 and counts.min() > 100
    assert sample_triplets(2, 10, rng).shape == (0, 3)


def test_global_depth_scale_cancels_in_solver():
    rng = np.random.default_rng(5)
    trial = simulate_points(rng, 30)
    tri = sample_triplets(30, 200, rng)
    f1, s1, ok1 = solve_triplets(trial.x, trial.d, trial.p, tri)
    f2, s2, ok2 = solve_triplets(trial.x, 1.37 * trial.d, trial.p, tri)
    assert (ok1 == ok2).all()
    np.testing.assert_allclose(f2[ok2], f1[ok1], rtol=1e-9)
    np.testing.assert_allclose(s2[ok2], 1.37 ** 2 * s1[ok1], rtol=1e-9)
