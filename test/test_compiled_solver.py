"""The compiled triplet solve (fcop_ros.core.solver) against its numpy path: the same validity and
the same focal and scale_sq (to 1e-12 relative; in practice the same bits) on simulated triplets,
on random triplets of shared points and on degenerate ones."""
import numpy as np
import pytest

from fcop_ros.core import compiled, solver
from fcop_ros.synthetic import simulate_triplet_batch

pytestmark = pytest.mark.skipif(compiled.numba is None, reason="numba is not installed")


def _both_ways(monkeypatch, fn):
    """fn() with the kernels, then with the numpy paths."""
    monkeypatch.setattr(compiled, "ENABLED", True)
    fast = fn()
    monkeypatch.setattr(compiled, "ENABLED", False)
    return fast, fn()


def _assert_same_solution(fast, slow):
    (f1, s1, ok1), (f2, s2, ok2) = fast, slow
    np.testing.assert_array_equal(ok1, ok2)
    np.testing.assert_allclose(f1, f2, rtol=1e-12, atol=0)
    np.testing.assert_allclose(s1, s2, rtol=1e-12, atol=0)
    for v in (f1, s1):
        assert np.isfinite(v).all()
        assert (v[~ok1] == 0.0).all()


def _degenerate_points(rng):
    """Points whose triplets below are degenerate in every way the solver knows, next to
    ordinary ones: (x, d, p, triplets)."""
    x, d, p, _, _ = simulate_triplet_batch(rng, 4)
    x, d, p = x.reshape(-1, 2).copy(), d.reshape(-1).copy(), p.reshape(-1, 3).copy()
    d[3:6] = 2.0  # triplet 1: equal depths (the system is homogeneous)
    x[6:9] = x[6] * np.array([[1.0], [2.0], [3.0]])  # triplet 2: on one ray through the centre
    d[6:9] = d[6] * np.array([1.0, 2.0, 3.0])
    x[9:12], p[9:12] = 0.0, 0.0  # triplet 3: nothing but depth (NaN-free zeros)
    extra = np.array([[0, 0, 1], [1, 1, 1], [0, 1, 0],  # repeated points
                      [0, 1, 2], [2, 1, 0], [1, 2, 0]])  # an ordinary triplet, permuted
    tri = np.concatenate([np.arange(12).reshape(4, 3), extra])
    return x, d, p, tri


def test_simulated_triplets_agree(monkeypatch):
    rng = np.random.default_rng(11)
    n = 20_000
    x, d, p, _, _ = simulate_triplet_batch(rng, n)
    X, D, P = x.reshape(-1, 2), d.reshape(-1), p.reshape(-1, 3)
    tri = np.arange(3 * n).reshape(n, 3)
    fast, slow = _both_ways(monkeypatch, lambda: solver.solve_triplets(X, D, P, tri))
    _assert_same_solution(fast, slow)
    assert fast[2].mean() > 0.999


def test_random_triplets_of_shared_points_agree(monkeypatch):
    """The estimator's pattern: many triplets of a few points, about half of them invalid
    (a random triplet of different objects' points has no consistent solution)."""
    rng = np.random.default_rng(12)
    x, d, p, _, _ = simulate_triplet_batch(rng, 500)
    X, D, P = x.reshape(-1, 2), d.reshape(-1), p.reshape(-1, 3)
    tri = solver.sample_triplets(len(D), 30_000, rng)
    fast, slow = _both_ways(monkeypatch, lambda: solver.solve_triplets(X, D, P, tri))
    _assert_same_solution(fast, slow)
    assert 0.1 < fast[2].mean() < 0.9


def test_degenerate_triplets_agree(monkeypatch):
    x, d, p, tri = _degenerate_points(np.random.default_rng(13))
    fast, slow = _both_ways(monkeypatch, lambda: solver.solve_triplets(x, d, p, tri))
    _assert_same_solution(fast, slow)
    np.testing.assert_array_equal(fast[2], [True, False, False, False,
                                            False, False, False, True, True, True])


def test_strided_inputs_agree(monkeypatch):
    """Views (columns of a larger array, reversed triplets) give what their copies give."""
    rng = np.random.default_rng(14)
    x, d, p, _, _ = simulate_triplet_batch(rng, 300)
    big = np.concatenate([x.reshape(-1, 2), d.reshape(-1, 1), p.reshape(-1, 3)], axis=1)
    tri = solver.sample_triplets(900, 2000, rng)[::-1]
    fast, slow = _both_ways(monkeypatch, lambda: solver.solve_triplets(
        big[:, :2], big[:, 2], big[:, 3:], tri))
    _assert_same_solution(fast, slow)
