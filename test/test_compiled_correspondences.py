"""The compiled correspondence kernels and the numpy code they replace give the same instances:
extract_instances on world frames, noise presets, broken inputs, tiny and touching instances and
several option sets, each computed both ways in one process (the same pixels, image points and
random subsets; values equal up to rounding), and calibrated_nocs both ways."""
import numpy as np
import pytest

from fcop_ros.core import EstimatorOptions, compiled
from fcop_ros.core.correspondences import calibrated_nocs, extract_instances
from fcop_ros.synthetic import apply_noise, render_scene, scenes

pytestmark = pytest.mark.skipif(compiled.numba is None, reason="numba is not installed")

FIRST_SEED = 7700
_EST = EstimatorOptions()
#: extract_instances as the estimator calls it.
ESTIMATOR = dict(min_object_pixels=_EST.min_object_pixels, erode_px=_EST.erode_px,
                 denoise_radius=_EST.denoise_radius, outlier_sigma=_EST.outlier_sigma,
                 edge_sigma=_EST.edge_sigma, max_pixels=_EST.max_pixels,
                 max_instances=_EST.max_instances)
OPTION_SETS = {
    "estimator": ESTIMATOR,
    "function defaults": {},
    "no denoising": dict(ESTIMATOR, denoise_radius=0),
    "wide window, strict edges": dict(ESTIMATOR, denoise_radius=4, edge_sigma=1.0),
    "no erosion": dict(ESTIMATOR, erode_px=0),
    "two erosions, few pixels": dict(ESTIMATOR, erode_px=2, max_pixels=300),
    "no outlier or edge test": dict(ESTIMATOR, outlier_sigma=0.0, edge_sigma=0.0),
    "raw (no means at all)": dict(ESTIMATOR, outlier_sigma=0.0, denoise_radius=0),
    "always denoise": dict(ESTIMATOR, noise_floor=0.0),
    "never denoise": dict(ESTIMATOR, noise_floor=1.0),
    "two largest, small ones kept": dict(ESTIMATOR, max_instances=2, min_object_pixels=5),
}


def _both_ways(monkeypatch, fn):
    """fn() with the kernels, then with the numpy paths."""
    monkeypatch.setattr(compiled, "ENABLED", True)
    fast = fn()
    monkeypatch.setattr(compiled, "ENABLED", False)
    return fast, fn()


def _extract_both(monkeypatch, depth, nocs, mask, seed=0, **options):
    return _both_ways(monkeypatch, lambda: extract_instances(
        depth, nocs, mask, rng=np.random.default_rng(seed), **options))


def assert_same_instances(fast, slow):
    """The same instances, pixels and random subsets; values equal up to rounding."""
    assert [i.instance_id for i in fast] == [i.instance_id for i in slow]
    assert fast.skipped == slow.skipped
    for a, b in zip(fast, slow):
        assert (a.mask_pixels, a.valid_pixels) == (b.mask_pixels, b.valid_pixels)
        assert a.x.shape == b.x.shape == (len(a.d), 2)
        np.testing.assert_array_equal(a.x, b.x)
        np.testing.assert_allclose(a.d, b.d, rtol=1e-12, atol=0)
        np.testing.assert_allclose(a.p, b.p, rtol=1e-12, atol=1e-15)
        np.testing.assert_allclose(a.var_d, b.var_d, rtol=1e-12, atol=0)
        np.testing.assert_allclose(a.var_p, b.var_p, rtol=1e-12, atol=0)
        assert a.sigma_d == pytest.approx(b.sigma_d, rel=1e-12, abs=0)
        assert a.sigma_p == pytest.approx(b.sigma_p, rel=1e-12, abs=0)
        for arr in (a.x, a.d, a.p, a.var_d, a.var_p):
            assert arr.dtype == np.float64


@pytest.mark.parametrize("size", [(320, 240), (640, 480)])
@pytest.mark.parametrize("preset", ["predicted", "sensor"])
def test_world_frames(monkeypatch, preset, size):
    for k in range(3):
        fr = scenes.world_frame(preset, FIRST_SEED + k, size=size)
        fast, slow = _extract_both(monkeypatch, fr.depth, fr.nocs, fr.mask, seed=k, **ESTIMATOR)
        assert len(fast) > 0
        assert_same_instances(fast, slow)


@pytest.mark.parametrize("noise", ["moderate", "harsh"])
def test_noise_presets(monkeypatch, noise):
    for k in range(4):
        fr = apply_noise(render_scene(np.random.default_rng(k), 5, 600.0), noise,
                         np.random.default_rng(k))
        fast, slow = _extract_both(monkeypatch, fr.depth, fr.nocs, fr.mask, seed=k, **ESTIMATOR)
        assert len(fast) > 0
        assert_same_instances(fast, slow)


@pytest.mark.parametrize("name", sorted(OPTION_SETS))
def test_option_sets(monkeypatch, name):
    frames = [scenes.world_frame("predicted", FIRST_SEED + 10, size=(320, 240)),
              apply_noise(render_scene(np.random.default_rng(3), 5, 600.0), "harsh",
                          np.random.default_rng(3))]
    for k, fr in enumerate(frames):
        fast, slow = _extract_both(monkeypatch, fr.depth, fr.nocs, fr.mask, seed=k,
                                   **OPTION_SETS[name])
        assert_same_instances(fast, slow)


def _moderate_frame(seed=5):
    fr = apply_noise(render_scene(np.random.default_rng(seed), 5, 600.0), "moderate",
                     np.random.default_rng(seed))
    return fr.depth.copy(), fr.nocs.copy(), fr.mask.copy()


@pytest.mark.parametrize("case", sorted(scenes.BAD_CASES))
def test_bad_inputs(monkeypatch, case):
    """Whole-frame NaN, inf and zero depth, empty masks, zero or NaN NOCS, single pixels, tiny
    and planar objects."""
    depth, nocs, mask = _moderate_frame()
    scenes.BAD_CASES[case](depth, nocs, mask)
    fast, slow = _extract_both(monkeypatch, depth, nocs, mask, **ESTIMATOR)
    assert_same_instances(fast, slow)


def test_invalid_patches_and_types(monkeypatch):
    """Patches of NaN, inf, zero and negative depth, zero, NaN and out-of-range NOCS inside the
    objects; then the same frame as float32 images with an int32, a uint8 and a boolean mask,
    and with a principal point given."""
    depth, nocs, mask = _moderate_frame(6)
    rng = np.random.default_rng(0)
    ys, xs = np.nonzero(mask > 0)
    for bad in (np.nan, np.inf, 0.0, -1.0):
        pick = rng.choice(ys.size, 400, replace=False)
        depth[ys[pick], xs[pick]] = bad
    for bad in (0.0, np.nan, 1.5, -0.2):
        pick = rng.choice(ys.size, 400, replace=False)
        nocs[ys[pick], xs[pick]] = bad
    k = int(mask[ys[0], xs[0]])
    nocs[mask == k] = 0.0  # one instance without any NOCS prediction
    cases = [(depth, nocs, mask, {}),
             (depth.astype(np.float32), nocs.astype(np.float32), mask.astype(np.int32), {}),
             (depth, nocs, mask.astype(np.uint8), dict(principal_point=(300.25, 250.5))),
             (depth, nocs, mask > 0, {})]
    for d, n, m, extra in cases:
        fast, slow = _extract_both(monkeypatch, d, n, m, **ESTIMATOR, **extra)
        assert k not in [i.instance_id for i in fast] or m.dtype == bool
        assert_same_instances(fast, slow)


def test_tiny_and_touching_instances(monkeypatch):
    """Instances cut into touching pieces (ids side by side, some of a few pixels), tiny
    instances at the image border, and a mask of many small ids (the histogram path)."""
    depth, nocs, mask = _moderate_frame(7)
    cut = mask.copy()
    ys, xs = np.nonzero(mask > 0)
    cut[ys, xs] = mask[ys, xs] + 5 * ((xs // 7 + ys // 9) % 3)  # up to 15: the per-id path
    cut[0:4, 0:4] = 16
    cut[-3:, -5:] = 12
    for opts in (ESTIMATOR, dict(ESTIMATOR, min_object_pixels=3, erode_px=0),
                 dict(ESTIMATOR, min_object_pixels=1, erode_px=0, denoise_radius=3)):
        fast, slow = _extract_both(monkeypatch, depth, nocs, cut, **opts)
        assert_same_instances(fast, slow)
    many = np.where(mask > 0, 1 + (np.arange(mask.size).reshape(mask.shape) // 13) % 400, 0)
    fast, slow = _extract_both(monkeypatch, depth, nocs, many, min_object_pixels=5,
                               erode_px=0, edge_sigma=2.0, max_instances=100)
    assert fast.skipped > 0
    assert_same_instances(fast, slow)


def test_calibrated_nocs(monkeypatch):
    fr = scenes.world_frame("predicted", FIRST_SEED + 20)
    frames = [(fr.depth, fr.nocs, fr.mask), _moderate_frame(8)]
    compared = 0
    for depth, nocs, mask in frames:
        for inst in extract_instances(depth, nocs, mask, rng=np.random.default_rng(0),
                                      **ESTIMATOR):
            fast, slow = _both_ways(monkeypatch, lambda: calibrated_nocs(inst))
            compared += fast.p is not inst.p
            assert (fast.p is inst.p) == (slow.p is inst.p)
            np.testing.assert_allclose(fast.p, slow.p, rtol=0, atol=1e-12)
            assert fast.p.shape == inst.p.shape
    assert compared >= 4


@pytest.mark.parametrize("dtype", ["int8", "uint8", "int16", "uint16", "int32", "uint32",
                                   "int64", "uint64"])
def test_mask_types(monkeypatch, dtype):
    """Every integer mask type (the compiled id pass reads the mask's bytes), negative ids as
    background, and a mask that is not C-contiguous."""
    depth, nocs, mask = _moderate_frame(9)
    m = mask.astype(dtype)
    if np.dtype(dtype).kind == "i":
        m[::7, ::5] = -1
        m[-40:, :40] = np.iinfo(dtype).min
    for mm in (m, np.asfortranarray(m)):
        fast, slow = _extract_both(monkeypatch, depth, nocs, mm, **ESTIMATOR)
        assert len(fast) > 0
        assert_same_instances(fast, slow)


@pytest.mark.parametrize("dtype", ["int8", "uint8", "int16", "uint64"])
def test_eroded_crops(dtype):
    """The compiled crop mask (compare, erode, stride in one pass) is cv2.erode's with a zero
    border, for random blobs, boxes inside and at the image's edge, 0-2 erosions and 7 and 25
    (beyond half of most boxes, where the row pass stops early), strides 1-3."""
    import cv2

    from fcop_ros.core.correspondences import _eroded_crop_k

    rng = np.random.default_rng(41)
    compared = 0
    for _ in range(60):
        h, w = (int(v) for v in rng.integers(1, 40, 2))
        m = np.zeros((h, w), np.int64)
        for iid in (1, 2, 3):
            y0, x0 = rng.integers(0, h), rng.integers(0, w)
            m[y0:y0 + rng.integers(1, h + 1), x0:x0 + rng.integers(1, w + 1)] = iid
        m[rng.random((h, w)) < 0.05] = rng.integers(0, 4)
        if np.dtype(dtype).kind == "i":
            m[rng.random((h, w)) < 0.05] = -1
        m = m.astype(dtype)
        raw = m.view(np.uint8).reshape(h, w * m.itemsize)
        r0, r1 = sorted(int(v) for v in rng.integers(0, h + 1, 2))
        c0, c1 = sorted(int(v) for v in rng.integers(0, w + 1, 2))
        if r1 == r0 or c1 == c0:
            continue
        for k in (0, 1, 2, 7, 25):
            for st in (1, 2, 3):
                want = m[r0:r1, c0:c1] == 1
                if k:
                    want = cv2.erode(want.astype(np.uint8), np.ones((3, 3), np.uint8),
                                     iterations=k, borderType=cv2.BORDER_CONSTANT,
                                     borderValue=0).astype(bool)
                got = _eroded_crop_k(raw, m.itemsize, 1, r0, r1, c0, c1, k, st)
                np.testing.assert_array_equal(got, want[::st, ::st])
                compared += 1
    assert compared >= 300


@pytest.mark.parametrize("dtype", ["int8", "uint8", "int16", "uint32", "int64"])
def test_id_pass_stops_at_a_large_id(dtype):
    """The compiled id pass counts and boxes ids up to 16 as the per-id numpy pass does
    (negative values are background) and gives up, for the histogram path, at a larger id."""
    from fcop_ros.core.correspondences import (
        _few_ids_and_boxes,
        _few_ids_and_boxes_compiled,
        _mask_bytes,
    )

    rng = np.random.default_rng(8)
    m = rng.integers(0, 17, (48, 64)).astype(dtype)
    if np.dtype(dtype).kind == "i":
        m[rng.random(m.shape) < 0.2] = -3
    fast = _few_ids_and_boxes_compiled(_mask_bytes(m), m.dtype, 16, 5)
    slow = _few_ids_and_boxes(m, 16, 5)
    assert fast is not None
    np.testing.assert_array_equal(fast[0], slow[0])
    np.testing.assert_array_equal(fast[1], slow[1])
    assert fast[2] == slow[2]
    m[40, 50] = 17
    assert _few_ids_and_boxes_compiled(_mask_bytes(m), m.dtype, 16, 5) is None


def test_median_and_selection_are_numpys():
    """The kernels' median (_median_k, by _select_k's branch-free quickselect) is np.median's
    value bit for bit, on random, sorted, constant and few-valued data of every size around the
    bracketing threshold (256), and the selection leaves no larger value before the rank and no
    smaller one after it."""
    from fcop_ros.core.correspondences import _median_k, _select_k

    # Compiled, as the kernels run them (called from Python, the helpers would run as Python).
    median = compiled.numba.njit(lambda v, n: _median_k(v, n))
    select = compiled.numba.njit(lambda v, lo, hi, k: _select_k(v, lo, hi, k))
    rng = np.random.default_rng(23)
    for trial in range(1500):
        n = int(rng.integers(1, 1300))
        kind = trial % 5
        v = (rng.standard_normal(n) * 10.0 ** rng.integers(-6, 6) if kind == 0
             else rng.integers(0, 2 + trial % 9, n).astype(float) if kind == 1
             else np.sort(rng.standard_normal(n)) if kind == 2
             else np.full(n, 0.25) if kind == 3
             else np.sort(rng.standard_normal(n))[::-1].copy())
        assert median(v.copy(), n) == np.median(v), (trial, n)
        lo = int(rng.integers(0, n))
        hi = int(rng.integers(lo, n))
        k = int(rng.integers(lo, hi + 1))
        w = v.copy()
        select(w, lo, hi, k)
        assert w[k] == np.sort(v[lo:hi + 1])[k - lo]
        assert np.all(w[lo:k] <= w[k]) and np.all(w[k + 1:hi + 1] >= w[k])
        assert np.array_equal(np.sort(w[lo:hi + 1]), np.sort(v[lo:hi + 1]))
