"""The compiled kernels of the vote stage against their numpy paths: the triplet solve (the same
validity, focal and scale_sq to 1e-12 relative; in practice the same bits) on simulated, shared,
degenerate and strided inputs; the estimator's votes (the same draws and votes); the stabbing's
deepest start. And combine's Python-float sums, which must give numpy's bits."""
import numpy as np
import pytest

from fcop_ros.core import combine, compiled, estimator, solver, stabbing
from fcop_ros.synthetic import simulate_points, simulate_triplet_batch

needs_numba = pytest.mark.skipif(compiled.numba is None, reason="numba is not installed")


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


@needs_numba
def test_simulated_triplets_agree(monkeypatch):
    rng = np.random.default_rng(11)
    n = 20_000
    x, d, p, _, _ = simulate_triplet_batch(rng, n)
    X, D, P = x.reshape(-1, 2), d.reshape(-1), p.reshape(-1, 3)
    tri = np.arange(3 * n).reshape(n, 3)
    fast, slow = _both_ways(monkeypatch, lambda: solver.solve_triplets(X, D, P, tri))
    _assert_same_solution(fast, slow)
    assert fast[2].mean() > 0.999


@needs_numba
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


@needs_numba
def test_degenerate_triplets_agree(monkeypatch):
    x, d, p, tri = _degenerate_points(np.random.default_rng(13))
    fast, slow = _both_ways(monkeypatch, lambda: solver.solve_triplets(x, d, p, tri))
    _assert_same_solution(fast, slow)
    np.testing.assert_array_equal(fast[2], [True, False, False, False,
                                            False, False, False, True, True, True])


@needs_numba
def test_strided_inputs_agree(monkeypatch):
    """Views (columns of a larger array, reversed triplets) give what their copies give."""
    rng = np.random.default_rng(14)
    x, d, p, _, _ = simulate_triplet_batch(rng, 300)
    big = np.concatenate([x.reshape(-1, 2), d.reshape(-1, 1), p.reshape(-1, 3)], axis=1)
    tri = solver.sample_triplets(900, 2000, rng)[::-1]
    fast, slow = _both_ways(monkeypatch, lambda: solver.solve_triplets(
        big[:, :2], big[:, 2], big[:, 3:], tri))
    _assert_same_solution(fast, slow)


def _objects(rng, sizes):
    out = []
    for n in sizes:
        t = simulate_points(rng, n, depth_noise=0.002, nocs_noise=0.01)
        out.append((t.x, t.d, t.p))
    return out


@needs_numba
def test_object_votes_agree(monkeypatch):
    """The estimator's vote stage: the same draws (the generator ends in the same state), the
    same votes in the same order, the same owners; an object of two points draws nothing."""
    objects = _objects(np.random.default_rng(15), (40, 2, 700, 3, 150))
    xs, ds, ps = zip(*objects)

    def votes():
        rng = np.random.default_rng(16)
        f, owner = solver.object_votes(xs, ds, ps, 900, rng, (300.0, 1500.0))
        return f, owner, rng.integers(2**62)

    (f1, o1, next1), (f2, o2, next2) = _both_ways(monkeypatch, votes)
    assert next1 == next2
    np.testing.assert_array_equal(o1, o2)
    np.testing.assert_allclose(f1, f2, rtol=1e-12, atol=0)
    assert set(o1.tolist()) == {0, 2, 3, 4} and ((f1 >= 300) & (f1 <= 1500)).all()


@needs_numba
@pytest.mark.parametrize("n", [1, 2, 5, 300, 5000, 40_000])
def test_stabbing_agrees(monkeypatch, n):
    """The compiled deepest start (a merge of the sorted ends) against numpy's searches, both
    stabbing functions: spread, clustered and tied votes (rounded: many equal ends, intervals
    that only touch), with a few non-finite ones."""
    rng = np.random.default_rng(17 + n)
    for votes in (np.exp(rng.normal(6.4, 0.3, n)), np.exp(rng.normal(6.4, 0.01, n)),
                  np.round(rng.normal(600, 40, n), -1), rng.integers(0, 4, n) * 10.0 + 500):
        votes[rng.random(n) < 0.01] = np.nan
        c, r = np.log(votes), np.log1p(0.05)

        def both():
            return [stabbing.stab_equal_width(c, r), stabbing.interval_stabbing(c - r, c + r),
                    stabbing.interval_stabbing(votes - 10.0, votes + 10.0)]

        fast, slow = _both_ways(monkeypatch, both)
        for a, b in zip(fast, slow):
            assert (a.point, a.count, a.region) == (b.point, b.count, b.region)
            np.testing.assert_array_equal(a.inliers, b.inliers)


@needs_numba
def test_warm_up_compiles_what_solve_triplets_runs(monkeypatch):
    """solve_triplets, whatever views and integer types it gets, runs the kernel signature that
    the warm-up (the estimator's votes) compiled: no compilation waits in a later call."""
    monkeypatch.setattr(compiled, "ENABLED", True)
    compiled.warm_up()
    before = list(solver._triplets_kernel.signatures)
    rng = np.random.default_rng(18)
    x, d, p, _, _ = simulate_triplet_batch(rng, 50)
    big = np.concatenate([x.reshape(-1, 2), d.reshape(-1, 1), p.reshape(-1, 3)], axis=1)
    solver.solve_triplets(big[:, :2], big[:, 2], big[:, 3:],
                          solver.sample_triplets(150, 10, rng).astype(np.int32)[::2])
    # (Two signatures after a fresh compilation: the votes kernel's call compiles one too.)
    assert solver._triplets_kernel.signatures == before and len(before) >= 1


def test_combine_sums_as_numpy():
    """combine's Python sums give numpy's bits (its pairwise order), so combine_objects gives
    what it gave on numpy arrays."""
    rng = np.random.default_rng(19)
    for n in [*range(0, 40), 127, 128, 129, 300, 1001]:
        a = rng.normal(size=n) * 10.0 ** rng.integers(-6, 6, n)
        assert combine._sum(a.tolist()) == float(np.sum(a))


def _numpy_combine_objects(y, v, noise, tau0, nu0, reject=3.0):
    """combine_objects written on numpy arrays: the reference."""
    noise = np.minimum(noise, v)

    def comb(y, v, noise):
        k, w = y.size, 1.0 / v
        mean_fe = float(np.sum(w * y) / w.sum())
        tau2_dl = 0.0
        if k > 1:
            q = float(np.sum(w * (y - mean_fe) ** 2))
            c = w.sum() - np.sum(w * w) / w.sum()
            tau2_dl = max(0.0, (q - (k - 1)) / c) if c > 0 else 0.0
        tau2 = (nu0 * tau0 ** 2 + (k - 1) * tau2_dl) / (nu0 + k - 1)
        wn = 1.0 / noise
        return (float(np.sum(wn * y) / wn.sum()),
                float(np.sum(wn * wn * (v + tau2)) / (wn.sum() * wn.sum())),
                float(1.0 / wn.sum()), float(tau2))

    used = np.isfinite(y) & np.isfinite(v) & (v > 0) & np.isfinite(noise) & (noise > 0)
    while used.sum() >= 3:
        idx = np.flatnonzero(used)
        z = np.zeros(idx.size)
        for n, i in enumerate(idx):
            rest = idx[idx != i]
            mean, var, _, tau2 = comb(y[rest], v[rest], noise[rest])
            z[n] = abs(y[i] - mean) / np.sqrt(v[i] + tau2 + var)
        if z.max() <= reject:
            break
        used[idx[int(np.argmax(z))]] = False
    return (*comb(y[used], v[used], noise[used]), used) if used.any() else None


def test_combine_objects_as_on_numpy_arrays():
    rng = np.random.default_rng(20)
    for t in range(3000):
        n = int(rng.integers(0, 12))
        y = 6.4 + rng.normal(0, 10.0 ** rng.uniform(-4, -0.5), n)
        if t % 3 == 0 and n:
            y[rng.integers(n)] += rng.normal(0, 0.3)  # an outlier to drop
        v = 10.0 ** rng.uniform(-7, -2, n)
        noise = v * 10.0 ** rng.uniform(-3, 0.3, n)  # some above v: clipped to it
        if t % 5 == 0 and n:
            v[rng.integers(n)] = (np.nan, 0.0, np.inf)[t % 3]
        tau0, nu0 = ((0.005, 2.0), (0.0, 2.0), (0.02, 0.5))[t % 3]
        got = combine.combine_objects(y, v, noise, tau0, nu0)
        want = _numpy_combine_objects(y, v, noise, tau0, nu0)
        assert (got is None) == (want is None)
        if got is not None:
            assert (got.mean, got.var, got.noise, got.tau2) == want[:4]
            np.testing.assert_array_equal(got.used, want[4])


@needs_numba
def test_extent_agrees(monkeypatch):
    """An object's image scale (RMS image radius over RMS NOCS radius) and median depth (its
    extent's factors), compiled and in numpy, agree to 1e-12 relative for odd and even counts
    (the median of an even count is the mean of the middle two) and points far from the
    principal point."""
    from fcop_ros.core.correspondences import Instance

    rng = np.random.default_rng(22)
    for n in (1, 2, 3, 10, 999, 2000):
        for _ in range(5):
            x = rng.normal(size=(n, 2)) * 50.0 + rng.normal(size=2) * 300.0
            d = rng.uniform(0.4, 2.0, n)
            inst = Instance(1, x, d, rng.random((n, 3)), np.zeros(n), 0.0, 0.0, n, n)
            fast, slow = _both_ways(monkeypatch, lambda: estimator._image_scale_depth(inst))
            np.testing.assert_allclose(fast, slow, rtol=1e-12, atol=0)


@needs_numba
def test_nocs_spread_agrees(monkeypatch):
    """The estimator's NOCS spread, compiled and per column, gives the bits of the formula it
    replaces (numpy's pairwise mean emulated to the last bit) at sizes around its blocks."""
    rng = np.random.default_rng(21)
    sizes = [1, 2, 7, 8, 9, 127, 128, 129, 136, 255, 257, 1000, 2000, 9000, 20_001]
    for n in sizes:
        for _ in range(5):  # points of very different distances, so that order shows
            p = rng.normal(size=(n, 3)) * 10.0 ** rng.uniform(-3, 3, (n, 1)) + rng.normal(size=3)
            want = np.sqrt(np.mean(np.sum((p - p.mean(0)) ** 2, axis=1)))
            fast, slow = _both_ways(monkeypatch, lambda: estimator._nocs_spread(p))
            assert fast == want and slow == want
