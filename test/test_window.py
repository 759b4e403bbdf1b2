"""The sliding window: evidence before a focal, convergence, zoom re-convergence, limits."""
import functools

import numpy as np
import pytest

from fcop_ros import FocalWindow, estimate_focal
from fcop_ros.core.estimator import FocalEstimate
from fcop_ros.synthetic import apply_noise, render_scene


@functools.lru_cache(maxsize=None)
def frame_estimate(seed, focal, preset):
    """Estimate of a small (320x240) rendered frame with the given true focal length."""
    fr = render_scene(np.random.default_rng(seed), 4, focal, 320, 240, distance_range=(0.5, 0.9))
    fr = apply_noise(fr, preset, np.random.default_rng(seed + 777))
    return estimate_focal(fr.depth, fr.nocs, fr.mask, seed=seed)


def empty_estimate():
    return FocalEstimate(None, (0.0, 0.0), (0, 0), reason="nothing")


def test_no_focal_without_evidence():
    w = FocalWindow(min_frames=3)
    assert w.current.focal is None
    for k in range(5):
        assert w.add(empty_estimate(), k * 0.1).focal is None
    r1 = w.add(frame_estimate(0, 300.0, "mild"), 1.0)
    assert r1.focal is None and "frames" not in r1.reason or r1.frames == 6
    w2 = FocalWindow(min_frames=3)
    w2.add(frame_estimate(0, 300.0, "mild"), 0.0)
    assert w2.add(frame_estimate(1, 300.0, "mild"), 0.1).focal is None  # 2 of 3 frames
    assert w2.add(frame_estimate(2, 300.0, "mild"), 0.2).focal is not None


def test_window_converges_and_reports_confidence():
    w = FocalWindow(max_frames=20)
    for k in range(20):
        r = w.add(frame_estimate(k, 300.0, "moderate"), k / 30)
    assert r.frames == 20 and r.support > 100 and 0 < r.confidence <= 1 and r.spread is not None
    single = [abs(frame_estimate(k, 300.0, "moderate").focal / 300 - 1) for k in range(20)]
    # The window is better than the typical single frame.
    assert abs(r.focal / 300 - 1) < np.median(single)
    assert abs(r.focal / 300 - 1) < 0.01


# Window error bounds on these 320x240 sequences. Measured (this commit, frames 10-24 before and
# 33-44 after the zoom): mild within 0.8% and 0.4%; harsh within 3.9% and 3.5% (the harsh preset
# biases small images low by 2-3%). A window that averaged old and new would be ~10% off.
ZOOM_BOUND = {"mild": 0.015, "harsh": 0.045}


@pytest.mark.parametrize("preset", ["mild", "harsh"])
def test_reconverges_after_zoom(preset):
    w = FocalWindow(max_frames=30)
    for k in range(25):
        w.add(frame_estimate(k, 300.0, preset), k / 30)
    assert abs(w.current.focal / 300 - 1) < ZOOM_BOUND[preset]
    errors, changed_at = [], None
    for k in range(25, 45):
        r = w.add(frame_estimate(k, 390.0, preset), k / 30)
        if r.changed and changed_at is None:
            changed_at = k
        errors.append(None if r.focal is None else abs(r.focal / 390 - 1))
    assert changed_at is not None and changed_at <= 25 + 5
    # After the change the window follows the new value and does not average old and new.
    assert all(e is not None and e < ZOOM_BOUND[preset] for e in errors[8:])
    assert w.changes == 1


def test_max_frames_max_age_and_reset():
    w = FocalWindow(max_frames=5, max_age=0.25)
    for k in range(10):
        w.add(frame_estimate(k % 3, 300.0, "clean"), k * 0.1)
    assert len(w) == 3  # stamps 0.7, 0.8, 0.9 are within 0.25 s of 0.9
    w.reset()
    assert len(w) == 0 and w.current.focal is None


def test_invalid_settings_are_refused():
    with pytest.raises(ValueError):
        FocalWindow(max_frames=0)
    with pytest.raises(ValueError):
        FocalWindow(max_age=-1)
    with pytest.raises(ValueError):
        FocalWindow(noise_bound=0)
