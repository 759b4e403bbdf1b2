"""fit_objects' compiled kernel and its numpy code give the same fits: every ObjectFits field, on
the instances of world frames of both presets and on bad cases, computed both ways in one
process.

The tolerances are rounding-level (the kernel sums in another order and solves the 3x3 and the
normal equations with other routines). Objects whose NOCS span less than the estimator's
``min_nocs_spread`` are compared only in their pixel counts: their fit is ill-posed (for NOCS of
one colour, the SVD of a covariance made of rounding errors), so either path's values are
rounding noise, and the estimator drops such objects.
"""
from dataclasses import fields

import numpy as np
import pytest

from fcop_ros.core import EstimatorOptions, compiled
from fcop_ros.core.camera import image_centre
from fcop_ros.core.correspondences import Instance, extract_instances
from fcop_ros.core.object_fit import ObjectFits, fit_objects
from fcop_ros.synthetic import scenes

pytestmark = pytest.mark.skipif(compiled.numba is None, reason="numba is not installed")

FIRST_SEED = 7600
FOCAL_FIT = dict(max_pixels=EstimatorOptions().fit_pixels,
                 iterations=EstimatorOptions().fit_iterations)  # as estimate_focal calls it
POSE_FIT = dict(fix_focal=True, proper=True, iterations=6)  # as estimate_poses calls it
EXACT = ("pixels", "mirrored", "ok")


def _instances(preset, seed):
    fr = scenes.world_frame(preset, seed)
    h, w = fr.depth.shape
    return extract_instances(fr.depth, fr.nocs, fr.mask, image_centre(w, h),
                             rng=np.random.default_rng(seed)), fr.focal


def _spread(inst):
    return np.sqrt(np.mean(np.sum((inst.p - inst.p.mean(0)) ** 2, axis=1)))


def _both_ways(monkeypatch, instances, focal0, seed=0, **kw):
    """fit_objects with the kernel, then with the numpy code, on the same pixel draws."""
    out = []
    for enabled in (True, False):
        monkeypatch.setattr(compiled, "ENABLED", enabled)
        out.append(fit_objects(instances, focal0, rng=np.random.default_rng(seed), **kw))
    return out


def _assert_same(fast: ObjectFits, slow: ObjectFits, instances, ill_posed=()):
    """Every field alike for the well-posed objects; the pixel counts for all."""
    np.testing.assert_array_equal(fast.pixels, slow.pixels)
    posed = np.array([_spread(i) >= EstimatorOptions().min_nocs_spread for i in instances])
    posed[list(ill_posed)] = False
    for fl in fields(ObjectFits):
        a, b = getattr(fast, fl.name)[posed], getattr(slow, fl.name)[posed]
        if fl.name in EXACT:
            np.testing.assert_array_equal(a, b, err_msg=fl.name)
        elif fl.name == "inlier_ratio":  # a count of weights above 0.5: equal
            np.testing.assert_allclose(a, b, rtol=0, atol=1e-12, err_msg=fl.name)
        else:
            np.testing.assert_allclose(a, b, rtol=1e-6, atol=1e-9, err_msg=fl.name)
    return int(posed.sum())


@pytest.mark.parametrize("preset", ["predicted", "sensor"])
@pytest.mark.parametrize("kw", [FOCAL_FIT, POSE_FIT], ids=["focal", "pose"])
def test_world_frames(monkeypatch, preset, kw):
    compared = 0
    for k in range(6):
        instances, focal = _instances(preset, FIRST_SEED + k)
        # Start off the true focal length, as the estimator's vote does.
        fast, slow = _both_ways(monkeypatch, instances, 1.05 * focal, seed=k, **kw)
        compared += _assert_same(fast, slow, instances)
    assert compared >= 12


def _object(rng, n, focal=500.0, mirror=False, flat=False):
    """A noisy box of NOCS seen at ``focal``: n pixels, optionally a mirrored NOCS or a flat
    image footprint (every pixel at one whole-pixel image point, so that its mean is exact)."""
    p = rng.uniform(0.1, 0.9, (n, 3))
    ang = rng.uniform(-1, 1, 3)
    th = np.linalg.norm(ang)
    kx = np.array([[0, -ang[2], ang[1]], [ang[2], 0, -ang[0]], [-ang[1], ang[0], 0]]) / th
    R = np.eye(3) + np.sin(th) * kx + (1 - np.cos(th)) * kx @ kx
    X = 0.3 * (p - 0.5) @ R.T + np.array([0.1, -0.05, 1.5])
    x = focal * X[:, :2] / X[:, 2:] + rng.normal(0, 0.5, (n, 2))
    if flat:
        x[:] = np.round(x[0])
    d = X[:, 2] + rng.normal(0, 2e-3, n)
    if mirror:
        p = p[:, [1, 0, 2]]
    return Instance(0, x, d, p, np.full(n, 4e-6), 2e-3, 0.0, n, n)


@pytest.mark.parametrize("kw", [FOCAL_FIT, POSE_FIT, dict(depth_tilt=False),
                                dict(fix_focal=True, depth_tilt=False, max_pixels=50),
                                dict(iterations=1), dict(iterations=2, proper=True)],
                         ids=["focal", "pose", "no-tilt", "fixed-no-tilt", "one-iteration",
                              "two-iterations"])
def test_bad_cases(monkeypatch, kw):
    """A mirrored NOCS, a tiny object (too few pixels to be ok), a small one, and a noisy
    clean one, fitted together, with the fit's options varied."""
    rng = np.random.default_rng(11)
    instances = [_object(rng, 400), _object(rng, 300, mirror=True), _object(rng, 5),
                 _object(rng, 30), _object(rng, 700)]
    fast, slow = _both_ways(monkeypatch, instances, 560.0, **kw)
    assert _assert_same(fast, slow, instances) == 5
    assert slow.mirrored[1] and not slow.ok[2]


def test_singular_system(monkeypatch):
    """An object whose pixels share one image point has no depth-tilt regressor (exactly zero):
    its normal equations are exactly singular, and the numpy code's batched inverse then gives
    every object an infinite variance; the kernel does the same."""
    rng = np.random.default_rng(12)
    instances = [_object(rng, 300), _object(rng, 200, flat=True)]
    fast, slow = _both_ways(monkeypatch, instances, 560.0)
    # The flat object's own fit is ill-posed too (one image point does not fix f).
    _assert_same(fast, slow, instances, ill_posed=[1])
    assert np.isinf(slow.var_log_focal).all() and np.isinf(fast.var_log_focal).all()


def test_padding_both_ways(monkeypatch):
    """_pad's compiled row gather gives the numpy path's arrays and draws, and instances of other
    types or layouts (float32, non-contiguous) take the numpy path alongside."""
    from fcop_ros.core.object_fit import _pad

    insts, _ = _instances("predicted", FIRST_SEED)
    a, b = insts[0], insts[-1]
    odd = [Instance(a.instance_id, a.x.astype(np.float32), a.d, a.p, a.var_d, a.sigma_d,
                    a.sigma_p, a.mask_pixels, a.valid_pixels, a.var_p),
           Instance(b.instance_id, np.asfortranarray(b.x), b.d, b.p[::-1][::-1], b.var_d,
                    b.sigma_d, b.sigma_p, b.mask_pixels, b.valid_pixels, b.var_p)]
    for case in (list(insts), list(insts) + odd):
        out = {}
        for enabled in (True, False):
            monkeypatch.setattr(compiled, "ENABLED", enabled)
            out[enabled] = _pad(case, 300, np.random.default_rng(3))
        for fast, slow in zip(out[True], out[False]):
            assert fast.dtype == slow.dtype
            np.testing.assert_array_equal(fast, slow)
