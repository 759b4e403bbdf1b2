"""The compiled kernels (fcop_ros.core.compiled) and the numpy code they replace give the same
estimates: the whole frame estimate, poses included, on world frames of both presets and on the
old noise presets, computed once each way in one process."""
import numpy as np
import pytest

from fcop_ros import estimate_focal
from fcop_ros.core import compiled
from fcop_ros.synthetic import apply_noise, render_scene, scenes

pytestmark = pytest.mark.skipif(compiled.numba is None, reason="numba is not installed")

FIRST_SEED = 7500


def _frames():
    out = [scenes.world_frame(preset, FIRST_SEED + k) for k in range(6)
           for preset in ("predicted", "sensor")]
    out += [apply_noise(render_scene(np.random.default_rng(k), 4, 600.0), "harsh",
                        np.random.default_rng(k)) for k in range(3)]
    return out


def _both_ways(monkeypatch, fn):
    """fn() with the kernels, then with the numpy paths."""
    monkeypatch.setattr(compiled, "ENABLED", True)
    fast = fn()
    monkeypatch.setattr(compiled, "ENABLED", False)
    return fast, fn()


def test_frame_estimates_agree(monkeypatch):
    frames = _frames()
    fast, slow = _both_ways(monkeypatch, lambda: [
        estimate_focal(fr.depth, fr.nocs, fr.mask, seed=k) for k, fr in enumerate(frames)])
    compared = 0
    for a, b in zip(fast, slow):
        assert a.reason == b.reason
        assert (a.focal is None) == (b.focal is None)
        if a.focal is None:
            continue
        compared += 1
        assert a.focal == pytest.approx(b.focal, rel=1e-6)
        assert a.std_rel == pytest.approx(b.std_rel, rel=1e-4)
        assert a.inlier_count == b.inlier_count
        assert sorted(a.object_focals) == sorted(b.object_focals)
        assert sorted(a.mirrored) == sorted(b.mirrored)
        assert [o.instance_id for o in a.objects] == [o.instance_id for o in b.objects]
        for pa, pb in zip(a.objects, b.objects):
            np.testing.assert_allclose(pa.translation, pb.translation, rtol=0, atol=1e-6)
            np.testing.assert_allclose(pa.rotation, pb.rotation, rtol=0, atol=1e-6)
            assert pa.scale == pytest.approx(pb.scale, rel=1e-6)
    assert compared >= 12


def test_warm_up_reaches_every_kernel(monkeypatch):
    """The node's warm-up compiles every kernel, so no frame waits for a compilation."""
    monkeypatch.setattr(compiled, "ENABLED", True)
    compiled.warm_up()
    missed = [k.py_func.__qualname__ for k in compiled.KERNELS if not k.signatures]
    assert not missed


def test_float32_images_read_as_they_are(monkeypatch):
    """float32 images (the node's) give, bit for bit, what their float64 copies give: the
    correspondences kernel reads them as they are and widens each value exactly; and the
    warm-up has compiled that signature, so the first float32 frame waits for no compilation."""
    from fcop_ros.core import correspondences

    monkeypatch.setattr(compiled, "ENABLED", True)
    compiled.warm_up()
    before = list(correspondences._crop_kernel.signatures)
    for k in range(3):
        fr = scenes.world_frame("predicted", FIRST_SEED + 50 + k)
        d32, n32 = fr.depth.astype(np.float32), fr.nocs.astype(np.float32)
        a = estimate_focal(d32, n32, fr.mask, seed=k)
        b = estimate_focal(d32.astype(np.float64), n32.astype(np.float64), fr.mask, seed=k)
        assert a.focal == b.focal and a.std_rel == b.std_rel
        assert a.object_focals == b.object_focals
        assert all(np.array_equal(pa.rotation, pb.rotation)
                   and np.array_equal(pa.translation, pb.translation) and pa.scale == pb.scale
                   for pa, pb in zip(a.objects, b.objects, strict=True))
    assert correspondences._crop_kernel.signatures == before


def test_flatness_agrees(monkeypatch):
    """The NOCS and pixel shape ratios that refuse a flat NOCS (estimator._flatness), kernel
    and numpy, on the instances of world frames (flat ones included)."""
    from fcop_ros.core.correspondences import calibrated_nocs, extract_instances
    from fcop_ros.core.estimator import _flatness

    insts = []
    for k, fr in enumerate(_frames()[:8]):
        nocs = fr.nocs.copy()
        if k % 2:
            nocs[..., k % 3] = np.where((fr.nocs != 0).any(2), 0.5, 0.0)
        insts.append([calibrated_nocs(i) for i in extract_instances(
            fr.depth, nocs, fr.mask, rng=np.random.default_rng(k))])
    fast, slow = _both_ways(monkeypatch, lambda: [_flatness(i, 600.0) for i in insts if i])
    for a, b in zip(fast, slow):
        np.testing.assert_allclose(a, b, rtol=1e-6, atol=1e-9)


def test_frame_checks_agree(monkeypatch):
    """The one compiled pass of the frame's sampled checks (NOCS range, median object depth)
    gives nocs_range's and _object_depth's numbers exactly, for every mask integer type (negative
    ids are background), float32 and float64 images, NOCS out of range and invalid values."""
    from fcop_ros.core.estimator import _frame_checks

    rng = np.random.default_rng(3)
    fr = _frames()[0]
    cases = []
    for dt in (np.float64, np.float32):
        for mt in (np.uint8, np.int8, np.uint16, np.int16, np.uint32, np.int32, np.uint64,
                   np.int64):
            nocs, depth = fr.nocs.astype(dt), fr.depth.astype(dt)
            nocs[rng.random(nocs.shape[:2]) < 0.05] *= 1.3
            nocs[rng.random(nocs.shape[:2]) < 0.02] = np.nan
            depth[rng.random(depth.shape) < 0.05] = np.nan
            mask = fr.mask.astype(mt)
            mask[rng.random(mask.shape) < 0.01] = 100  # an id with bit 6 set (int8: 0x64)
            if np.dtype(mt).kind == "i":
                mask[rng.random(mask.shape) < 0.01] = -3
            cases.append((depth, nocs, mask))
    cases.append((fr.depth, fr.nocs, np.zeros_like(fr.mask)))
    fast, slow = _both_ways(monkeypatch, lambda: [_frame_checks(*c) for c in cases])
    assert fast == slow
    assert sum(r[0] > 0 for r in fast) >= 12  # out-of-range NOCS were seen (15 of 17)
