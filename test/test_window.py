"""The sliding window: evidence before a focal, averaging by uncertainty, honest uncertainty,
zoom re-convergence, image-size changes, limits."""
from dataclasses import replace

import numpy as np
import pytest

from fcop_ros import FocalWindow, WindowOptions
from fcop_ros.core.estimator import FocalEstimate


def estimate(focal, std_rel=0.02, size=(640, 480), support=500, std_rel_noise=None,
             extents=None, radii=None):
    return FocalEstimate(focal, (319.5, 239.5), size, inlier_count=support, std_rel=std_rel,
                         std_rel_noise=std_rel_noise, object_extents=extents or {},
                         object_radii=radii or {})


def empty_estimate():
    return FocalEstimate(None, (0.0, 0.0), (640, 480), reason="nothing")


def frames(rng, n, focal=600.0, sigma=0.03, persistent=0.0):
    """Frame estimates with independent log-normal errors of ``sigma`` (their stated noise) plus
    one shared offset (their systematic budget)."""
    shared = rng.normal(0, persistent) if persistent else 0.0
    return [estimate(focal * np.exp(shared + rng.normal(0, sigma)), np.hypot(sigma, persistent),
                     std_rel_noise=sigma) for _ in range(n)]


def test_no_focal_without_evidence():
    w = FocalWindow(WindowOptions(min_frames=3))
    assert w.current.focal is None
    for k in range(5):
        assert w.add(empty_estimate(), k * 0.1).focal is None
    w2 = FocalWindow(WindowOptions(min_frames=3))
    w2.add(estimate(600.0), 0.0)
    r = w2.add(estimate(600.0), 0.1)
    assert r.focal is None and "2 frames with focal evidence (min_frames 3)" in r.reason
    assert w2.add(estimate(600.0), 0.2).focal is not None
    w3 = FocalWindow(WindowOptions(min_window_votes=1000))
    assert w3.add(estimate(600.0, support=400), 0.0).focal is None
    assert w3.add(estimate(600.0, support=700), 0.1).focal is not None


def test_window_averages_independent_errors_and_says_so():
    """30 frames with 3% independent errors: the window's error and its std_rel shrink by
    about sqrt(30); over 200 windows |error| <= 2 std_rel in 85-98% (measured 96.5%, median
    std_rel 0.60%, median error 0.40%)."""
    rng = np.random.default_rng(0)
    err, cover, std = [], [], []
    for _ in range(200):
        w = FocalWindow(WindowOptions(max_frames=30))
        for k, e in enumerate(frames(rng, 30)):
            r = w.add(e, k / 30)
        err.append(abs(np.log(r.focal / 600.0)))
        std.append(r.std_rel)
        cover.append(err[-1] <= 2 * r.std_rel)
    assert np.median(err) < 0.6 * 0.03 * 0.674  # 0.6x a single frame's median |error|
    assert 0.85 <= np.mean(cover) <= 0.98
    assert np.median(std) < 0.01


def test_window_does_not_claim_to_average_away_persistent_error():
    """Frames that share one 4% error (their stated systematic budget) agree closely; the window
    must stay about as unsure as a frame (the shared part cannot average away). Measured: coverage
    97.5% over 200 windows, median std_rel 4.00% (a frame's is 4.03%; a window that believed in
    averaging would say 0.74%)."""
    rng = np.random.default_rng(1)
    cover, std = [], []
    for _ in range(200):
        w = FocalWindow(WindowOptions(max_frames=30))
        for k, e in enumerate(frames(rng, 30, sigma=0.005, persistent=0.04)):
            r = w.add(e, k / 30)
        cover.append(abs(np.log(r.focal / 600.0)) <= 2 * r.std_rel)
        std.append(r.std_rel)
    assert 0.85 <= np.mean(cover) <= 0.98
    assert np.median(std) > 0.03


def test_a_lone_objects_prior_spread_counts_unless_the_frames_show_it_vary():
    """A lone object's frames carry the prior between-object spread (std_rel_prior) for the
    disagreement no other object can show. It may repeat through the window (a view that hardly
    changes), so the window keeps it in its budget, less what the frames' spread shows to vary.
    Frames with std_rel 4%, all of it prior, over 200 windows of 30: sharing one 4% error,
    coverage 94.5% at a median std_rel of 3.99% (left out of the budget, as before, 2.5% at
    0.06%); erring independently, 100% at 2.59% (the spread's lower bound keeps some)."""
    rng = np.random.default_rng(2)
    for shared, (low, high), (std_lo, std_hi) in ((True, (0.9, 0.98), (0.035, 0.045)),
                                                  (False, (0.98, 1.0), (0.02, 0.03))):
        cover, std = [], []
        for _ in range(200):
            w = FocalWindow(WindowOptions(max_frames=30))
            common = rng.normal(0, 0.04)
            for k in range(30):
                error = common + rng.normal(0, 0.003) if shared else rng.normal(0, 0.04)
                e = estimate(600.0 * np.exp(error), 0.04, std_rel_noise=0.003)
                e.std_rel_prior = 0.0399
                r = w.add(e, k / 30)
            cover.append(abs(np.log(r.focal / 600.0)) <= 2 * r.std_rel)
            std.append(r.std_rel)
        assert low <= np.mean(cover) <= high and std_lo < np.median(std) < std_hi, (
            shared, np.mean(cover), np.median(std))


def test_objects_that_disagree_lastingly_size_the_windows_std_rel():
    """Frames of five objects whose errors last through the window (each object its own,
    drawn at 4% or 0.5%), each frame stating 5%: the frames' budget, sized for the variance on
    average, says little of how these objects err; their lasting disagreement does, worth four
    objects against the frames' two. Over 200 windows of 30: objects disagreeing by 4%, median
    std_rel 3.17% at a median error of 1.49% (the frames' budget alone said 4.99%); agreeing
    to 0.5%, 2.88% at 0.20%; both covered in every window."""
    rng = np.random.default_rng(5)
    got = {}
    for spread in (0.04, 0.005):
        cover, std = [], []
        for _ in range(200):
            w = FocalWindow(WindowOptions(max_frames=30))
            lasting, noise = rng.normal(0, spread, 5), np.linspace(0.005, 0.015, 5)
            for t in range(30):
                y = lasting + rng.normal(0, noise)
                weight = noise ** -2.0
                e = estimate(600.0 * np.exp(weight @ y / weight.sum()), 0.05,
                             std_rel_noise=float(weight.sum() ** -0.5))
                e.object_focals = {i: (600.0 * np.exp(y[i]), 0.06, noise[i]) for i in range(5)}
                r = w.add(e, t / 30)
            cover.append(abs(np.log(r.focal / 600.0)) <= 2 * r.std_rel)
            std.append(r.std_rel)
        got[spread] = np.median(std)
        assert np.mean(cover) >= 0.95, (spread, np.mean(cover))
    assert 0.029 < got[0.04] < 0.035 and 0.026 < got[0.005] < got[0.04] - 0.002, got


def test_objects_do_not_discount_an_error_their_frame_shares_anew():
    """Ten objects whose frames each share a new 3% error (stated as the frames' noise) agree
    with each other to 1%: their agreement says nothing of the shared error, so the window
    keeps what the frames' spread shows. Over 100 windows of 30: coverage 99%, median
    std_rel 0.67% (the frames' noise over sqrt(30): 0.55%); with the spread mixed with the
    objects' agreement, 79% at 0.29%."""
    rng = np.random.default_rng(0)
    cover, std = [], []
    for _ in range(100):
        w = FocalWindow(WindowOptions(max_frames=30))
        noise = float(np.hypot(0.01 / np.sqrt(10), 0.03))
        for t in range(30):
            y = rng.normal(0, 0.03) + rng.normal(0, 0.01, 10)
            e = estimate(600.0 * np.exp(y.mean()), noise, std_rel_noise=noise)
            e.object_focals = {i: (600.0 * np.exp(y[i]), 0.01, 0.01) for i in range(10)}
            r = w.add(e, t / 30)
        cover.append(abs(np.log(r.focal / 600.0)) <= 2 * r.std_rel)
        std.append(r.std_rel)
    assert np.mean(cover) >= 0.95 and np.median(std) > 0.03 / np.sqrt(30), (
        np.mean(cover), np.median(std))


def test_object_evidence_without_a_usable_focal_or_noise_is_left_out():
    """Per-object entries whose noise is None, text, negative, zero, below 1e-12 or huge, or
    whose focal is None, text or not positive, are left out of the objects' disagreement: the
    window says what it says without them, and neither raises nor answers NaN."""
    good = {1: (600.0, 0.03, 0.01), 2: (630.0, 0.03, 0.01)}
    bad = {3: (610.0, 0.03, None), 4: (610.0, 0.03, "0.01"), 5: (610.0, 0.03, -0.01),
           6: (610.0, 0.03, 0.0), 7: (610.0, 0.03, 1e-80), 8: (610.0, 0.03, 1e200),
           9: (None, 0.03, 0.01), 10: ("610", 0.03, 0.01), 11: (-610.0, 0.03, 0.01)}
    results = []
    for objects in (good, {**good, **bad}):
        w = FocalWindow(WindowOptions(max_frames=30))
        for t in range(6):
            e = estimate(615.0 + t, 0.03, std_rel_noise=0.007)
            e.object_focals = dict(objects)
            r = w.add(e, t / 30)
        results.append((r.focal, r.std_rel))
    assert np.isfinite(results[1][1]) and results[1] == results[0]


def test_weights_by_uncertainty():
    w = FocalWindow()
    w.add(estimate(600.0, 0.01), 0.0)
    r = w.add(estimate(700.0, 0.10), 0.1)
    # Inverse-variance weights 100:1 in log f.
    assert r.focal == pytest.approx(600.0 * np.exp(np.log(700 / 600) / 101), rel=1e-9)


def test_a_budget_that_does_not_vary_weighs_no_frame():
    """Frames that share one systematic error, each with its own noise (0.2-3%) and its own
    stated budget (0.5-5%, unrelated to its error): the window weighs them by their noise.
    Measured over 200 windows: median distance of the window from the shared error 0.111%
    (the true noise's weights); weights 1 / std_rel^2 give 0.163%, weights by the noise and
    the budget's varying share (the window before 61467d1) 0.116%."""
    rng = np.random.default_rng(3)
    miss = []
    for _ in range(200):
        shared = rng.normal(0, 0.02)
        w = FocalWindow(WindowOptions(max_frames=30))
        for k in range(30):
            sigma, budget = rng.uniform(0.002, 0.03), rng.uniform(0.005, 0.05)
            e = estimate(600.0 * np.exp(shared + rng.normal(0, sigma)), np.hypot(sigma, budget),
                         std_rel_noise=sigma)
            r = w.add(e, k / 30)
        miss.append(abs(np.log(r.focal / 600.0) - shared))
    assert np.median(miss) < 0.00114

@pytest.mark.parametrize("step", [1.2, 0.8, 1.5])
def test_reconverges_after_zoom(step):
    """After a focal change of 20% or more with 3% frame noise: detected within 5 frames, the
    window within 5% of the new focal length for good within 15 frames, one restart."""
    rng = np.random.default_rng(2)
    w = FocalWindow(WindowOptions(max_frames=30))
    for k, e in enumerate(frames(rng, 30)):
        w.add(e, k / 30)
    errors, changed_at = [], None
    for k, e in enumerate(frames(rng, 30, focal=600.0 * step)):
        r = w.add(e, 1 + k / 30)
        if r.changed and changed_at is None:
            changed_at = k
        errors.append(abs(np.log(r.focal / (600.0 * step))))
    assert changed_at is not None and changed_at <= 5
    assert max(errors[15:]) < 0.05
    assert w.changes == 1


def test_zoom_among_frames_sharing_a_large_budget():
    """Frames that say std_rel 10%, nearly all of it a systematic error they share (+3%), with
    1% noise: a 22% zoom is detected within 5 frames and the window is within 5% for good
    within 15. (Floored by the frames' whole std_rel, the detector never saw it: a repeating
    budget cancels in a step. World sequences 7601 and 7602 at x1.25, test_world_accuracy.)"""
    rng = np.random.default_rng(8)
    shared, std, noise = 0.03, 0.10, 0.01

    def frame(focal):
        return estimate(focal * np.exp(shared + rng.normal(0, noise)), std, std_rel_noise=noise)

    w = FocalWindow(WindowOptions(max_frames=30))
    for k in range(20):
        w.add(frame(600.0), k / 30)
    errors, changed_at = [], None
    for k in range(20):
        r = w.add(frame(733.0), 1 + k / 30)
        if r.changed and changed_at is None:
            changed_at = k
        errors.append(abs(np.log(r.focal / 733.0)))
    assert changed_at is not None and changed_at <= 5
    assert max(errors[15:]) < 0.05
    assert w.changes == 1


def _scene(rng, zoom=1.0, objects=(90.0, 60.0, 40.0), jitter=0.01):
    """Object extents (px m) of a scene seen at ``zoom`` times the focal length."""
    return {i + 1: e * zoom * np.exp(rng.normal(0, jitter)) for i, e in enumerate(objects)}


def test_a_focal_step_the_image_scale_does_not_follow_is_no_zoom():
    """Tight frames (0.5%) whose focal lengths move by 20% while their objects' extents stay
    (a new view of objects whose errors moved, e.g. held-out sequence 905021): no restart.
    Without the extents the same frames restart the window."""
    for with_extents in (True, False):
        rng = np.random.default_rng(9)
        w = FocalWindow(WindowOptions(max_frames=30))
        for k in range(30):
            f = 600.0 * (1.2 if k >= 15 else 1.0) * np.exp(rng.normal(0, 0.005))
            w.add(estimate(f, 0.005, std_rel_noise=0.005,
                           extents=_scene(rng) if with_extents else None), k / 30)
        assert w.changes == (0 if with_extents else 1)


def _zoom_restarts(seed, n, extents):
    """(frame, frames kept) at each restart over n frames of a 22% zoom at frame 20, frames
    scattering by 6% (std_rel 10%, noise 1%), and the zoom measured where the window kept its
    frames through the change; ``extents(k, zoom, rng)`` gives frame k's extents, or its
    (extents, radii)."""
    rng = np.random.default_rng(seed)
    w = FocalWindow(WindowOptions(max_frames=30))
    restarts = []
    for k in range(n):
        zoom = 1.22 if k >= 20 else 1.0
        f = 600.0 * zoom * np.exp(rng.normal(0, 0.06))
        sizes = extents(k, zoom, rng)
        ext, rad = sizes if isinstance(sizes, tuple) else (sizes, None)
        r = w.add(estimate(f, 0.10, std_rel_noise=0.01, extents=ext, radii=rad), k / 30)
        if r.changed:
            restarts.append((k, r.frames) if r.zoom is None else (k, r.frames, round(r.zoom, 3)))
    return restarts


def test_a_zoom_the_image_scale_shows_is_seen_at_once():
    """Frames that scatter by 6% (std_rel 10%) through a 22% zoom: their focal lengths alone
    stand out at the eighth frame after it (frame 27); the objects' extents, which move by the
    zoom, show it at the second (frame 21), and the window restarts at the zoom itself (the
    median split there keeps one older frame)."""
    assert _zoom_restarts(10, 40, lambda k, zoom, rng: _scene(rng, zoom))[0] == (21, 2)
    assert _zoom_restarts(10, 40, lambda k, zoom, rng: None)[0][0] == 27


def test_frames_without_extents_are_skipped_by_the_image_scale():
    """The zoom of test_a_zoom_the_image_scale_shows_is_seen_at_once with every fifth frame
    without extents (all its objects cut by the image's edge), the first after the zoom among
    them: the scale still shows the zoom at its third frame (frame 22), and the window
    restarts at the first frame after the zoom that has extents (frame 21; frame 20 goes with
    the older frames). When one such frame turned the scale off for the whole window, the
    focal lengths alone saw the zoom at frame 31 (keeping 13 frames, one of them older)."""
    def every_fifth_cut(k, zoom, rng):
        extents = _scene(rng, zoom)
        return None if k % 5 == 0 else extents

    assert _zoom_restarts(10, 40, every_fifth_cut) == [(22, 2)]


def _replayed(focal, rows):
    """(the window, its last estimate) after a world sequence's frames, each row (error %,
    std_rel %, std_rel_noise %, std_rel_prior %, object extents, object radii) of the
    sequence's estimate_focal on its frames, the objects' ids from 1."""
    w = FocalWindow(WindowOptions(max_frames=30))
    for k, row in enumerate(rows):
        if row is None:  # a frame without evidence
            r = w.add(empty_estimate(), k / 30)
            continue
        err, std, noise, prior, extents, radii = row
        e = estimate(focal * np.exp(err / 100), std / 100, std_rel_noise=noise / 100,
                     extents=dict(extents if isinstance(extents, dict) else enumerate(extents, 1)),
                     radii=dict(radii if isinstance(radii, dict) else enumerate(radii, 1)))
        e.std_rel_prior = prior / 100
        r = w.add(e, k / 30)
    return w, r


def test_frames_that_cannot_tell_a_zoom_do_not_follow_a_scale_step():
    """Tuning `predicted` sequence 7090 at the preset's gain 0.4 (bench/world_accuracy.py
    --first-sequence 7000), whose
    objects leave the view: after frame 7 only four frames have a focal length, three of them
    +121% to +165% off and saying so (std_rel 77% to 26000%), the fourth -8% at 1800%. Object
    1's image scale is 105 px per NOCS unit while the edge cuts it and 199-211 once it is whole
    again (or another object took its id). The scale stepped, and the medians of the newer
    frames followed it: the window restarted at frame 29, at +165%. Frames whose step has a
    standard error larger than the scale's step cannot tell it from none, and do not follow."""
    rows = [
        (3.25, 19.73, 1.38, 4.27, {1: 134.55, 3: 189.92}, {1: 106.22, 3: 145.46}),
        (-5.75, 4.16, 1.02, 3.39, {1: 130.45}, {1: 105.1}),
        (3.12, 24.10, 1.01, 4.77, {1: 126.85, 3: 275.05}, {1: 105.14, 3: 166.36}),
        (0.00, 5.17, 1.08, 4.95, {1: 128.57}, {1: 106.95}),
        (-8.18, 5.22, 0.98, 4.03, {1: 124.94}, {1: 105.17}),
        (59.43, 118.47, 29.29, 5.48, {1: 127.55}, {1: 107.3}),
        (-2.86, 6.90, 2.72, 5.50, {}, {}),
        (-1.85, 5.48, 1.90, 4.75, {1: 118.66}, {1: 102.4}),
    ] + [None] * 8 + [
        (120.65, 26559.10, 26548.66, 65.54, {2: 340.43}, {2: 126.5}),
    ] + [None] * 4 + [
        (151.05, 1458.24, 1015.90, 8.77, {2: 256.32}, {2: 147.67}),
        None, None,
        (-8.03, 1838.95, 1836.22, 4.10, {1: 295.8}, {1: 211.04}),
    ] + [None] * 4 + [
        (164.84, 77.03, 7.66, 5.16, {1: 390.84}, {1: 199.36}),
    ]
    w, r = _replayed(488.2, rows)
    assert w.changes == 0 and abs(np.log(r.focal / 488.2)) < 0.03


def test_a_lone_objects_view_dependent_errors_are_no_zoom():
    """Two static single-object sequences of the tenth held-out model (bench/world_accuracy.py
    --heldout10), where the window restarted: `sensor` 1065001, whose last three frames erred
    +4.5%, +11.1% and +9.0% at a stated 5.3%, 3.1% and 2.7% (prior 5.2%, 2.6%, 2.5%, noise
    0.5%), and `predicted` 1065024, whose error drifted from -9% to +6% with the view at a
    stated 7-10% (prior 7%) while the camera's distance moved the object's image scale the other
    way. The prior part renews with the view, so it does not cancel between the segments of a
    split: counted in each segment's floor, neither is a zoom (the restart had left the first at
    +7.1%, at a stated 3.6%)."""
    sensor = [(-0.27, 0.88, 0.04, 0.04, 59.78, 99.83), (0.01, 0.91, 0.01, 0.01, 59.49, 99.61),
              (-0.04, 0.92, 0.01, 0.01, 56.57, 94.24), (-0.06, 1.06, 0.01, 0.0, 56.63, 94.37),
              (-0.01, 0.87, 0.01, 0.01, 57.94, 95.94), (0.1, 0.72, 0.02, 0.01, 59.77, 98.95),
              (-0.06, 1.09, 0.01, 0.01, 60.29, 98.59), (-0.03, 0.88, 0.01, 0.01, 58.47, 95.75),
              (-0.04, 0.8, 0.01, 0.01, 60.08, 98.69), (2.43, 5.13, 0.23, 3.86, 58.06, 95.97),
              (-0.0, 0.69, 0.01, 0.02, 59.41, 97.21), (0.48, 0.59, 0.06, 0.08, 60.56, 98.89),
              (2.49, 3.7, 0.19, 2.31, 59.37, 96.69), (0.15, 0.25, 0.02, 0.01, 61.87, 100.32),
              (0.0, 0.29, 0.01, 0.01, 58.27, 94.89), (-0.02, 0.39, 0.01, 0.02, 57.77, 93.44),
              (-0.01, 0.3, 0.01, 0.01, 60.06, 97.28), (-0.01, 0.28, 0.01, 0.04, 57.73, 93.68),
              (-0.0, 0.22, 0.01, 0.06, 57.0, 92.67), (-0.01, 0.47, 0.01, 0.02, 56.99, 92.48),
              (-0.02, 0.44, 0.01, 0.02, 56.32, 91.5), (-5.04, 5.13, 0.36, 4.66, 58.48, 95.09),
              (-4.93, 1.05, 0.5, 0.51, 59.32, 96.5), (-3.27, 3.11, 0.23, 2.59, 60.49, 98.89),
              (-0.05, 0.62, 0.01, 0.01, 59.09, 96.69), (-4.99, 1.1, 0.47, 0.8, 59.24, 97.02),
              (0.02, 0.71, 0.01, 0.02, 58.06, 95.85), (4.53, 5.3, 0.35, 5.18, 59.07, 97.98),
              (11.07, 3.12, 0.53, 2.59, 58.36, 97.11), (8.96, 2.68, 0.55, 2.49, 59.19, 98.83)]
    predicted = [
        (-9.08, 10.43, 0.79, 7.43, 125.65, 68.74), (-9.94, 9.33, 0.68, 7.49, 126.87, 68.81),
        (-11.06, 9.88, 0.65, 7.48, 126.49, 68.62), (-8.72, 8.19, 0.67, 7.44, 124.96, 68.53),
        (-9.66, 8.59, 0.64, 7.41, 124.92, 69.62), (-8.16, 8.29, 0.67, 7.41, 125.03, 70.01),
        (-5.27, 9.02, 0.62, 7.31, 121.91, 69.3), (-6.62, 7.92, 0.67, 7.36, 122.27, 69.67),
        (-6.69, 7.98, 0.57, 7.32, 120.99, 70.06), (-7.51, 9.18, 0.74, 7.26, 125.87, 73.22),
        (-8.71, 8.49, 0.73, 7.26, 131.46, 77.43), (-7.08, 11.55, 0.78, 7.19, 138.35, 81.91),
        (-2.33, 10.34, 0.8, 7.1, 132.68, 76.54), (1.75, 8.63, 0.84, 7.06, 124.28, 72.23),
        (0.68, 9.28, 0.8, 7.04, 116.59, 67.7), (2.82, 8.87, 0.95, 7.01, 108.81, 64.04),
        (5.94, 9.23, 0.93, 6.93, 104.02, 61.9), (5.79, 8.17, 1.15, 6.94, 95.97, 57.59),
        (6.01, 7.21, 1.22, 6.91, 90.68, 54.39)]
    errors = []
    for focal, rows in ((670.6, sensor), (1063.0, predicted)):
        w, r = _replayed(focal, [row[:4] + ([row[4]], [row[5]]) for row in rows])
        assert w.changes == 0, focal
        errors.append(abs(np.log(r.focal / focal)))
        assert errors[-1] <= 2 * r.std_rel, (focal, r.focal, r.std_rel)
    # Measured: sensor 0.02%; predicted 5.7% at a stated 7.2%.
    assert errors[0] < 0.001


def test_a_scale_with_one_older_frame_still_judges_a_step():
    """Tuning `predicted` sequence 7111's (gain 0.4) first 12 frames (bench/world_accuracy.py
    --first-sequence 7000): one object, cut by the image's edge in the first four frames (no
    sizes), whose focal error drifts with the view from +10% to -13% (std_rel 7-10%, nearly all
    of it the prior spread) while its extent and radius stay within 2%. The scale has one
    frame before the likeliest split and seven after; it can tell a 12% zoom from none and
    says none: no restart. When a scale needed three frames on either side to judge, the
    window restarted at frame 10 and kept the low frames, -10.3% at a stated 2.6%."""
    cut = [(10.2, 7.2, 1.23, 6.7), (4.2, 7.5, 1.0, 6.8), (3.2, 7.2, 0.9, 6.9),
           (-0.9, 8.2, 0.52, 7.0)]
    whole = [(-2.2, 9.6, 0.6, 7.0, [45.9], [52.0]), (-4.1, 9.7, 0.59, 7.0, [45.6], [51.9]),
             (-4.2, 8.5, 0.62, 7.0, [46.1], [52.6]), (-10.9, 8.5, 0.9, 6.9, [46.0], [52.9]),
             (-10.4, 7.2, 1.14, 6.7, [45.1], [52.3]), (-10.7, 7.2, 0.94, 6.8, [45.1], [52.4]),
             (-9.4, 7.3, 0.9, 6.8, [44.8], [52.6]), (-12.6, 6.9, 1.24, 6.5, [45.1], [53.0])]
    w, r = _replayed(1284.0, [row + ([], []) for row in cut] + whole)
    assert w.changes == 0 and r.frames == 12


def test_a_scale_step_the_newest_frame_takes_back_is_no_zoom():
    """Tuning `predicted` sequence 7033's (gain 0.4) first 15 frames (bench/world_accuracy.py
    --first-sequence 7000): three objects, two of them 7-9 px in radius, whose masks grow and
    shrink by a pixel together (20% of their radius). In frames 12 and 13 both are large and
    the focal lengths 6-8% high: the image radii stepped by 11% at 7 standard errors, and the
    focal lengths followed; in frame 14 both are back. A zoom persists, so the newest frame
    must lie nearer the newer level than the older: no restart. Without that, the window
    restarted at frame 14 (and the static 120 draws restarted 3 times, not 2)."""
    rows = [
        (2.77, 10.73, 0.17, 3.42, [28.51, 14.77, 11.86, 12.74], [22.02, 8.75, 7.47, 8.81]),
        (1.92, 4.28, 0.17, 3.58, [26.75, 13.5, 13.21], [20.93, 8.05, 8.34]),
        (2.56, 4.53, 0.14, 3.87, [27.85, 11.52, 11.93], [21.8, 6.86, 7.57]),
        (5.24, 8.25, 0.17, 4.32, [27.34, 14.36, 11.72], [21.43, 8.6, 7.48]),
        (3.50, 5.67, 0.17, 3.96, [28.51, 11.52, 11.83], [22.21, 6.95, 7.56]),
        (2.56, 8.07, 0.20, 4.00, [28.92, 11.43, 13.11], [22.61, 6.97, 8.45]),
        (3.20, 5.54, 0.17, 3.74, [28.66, 13.14, 12.95], [22.58, 7.99, 8.41]),
        (4.73, 6.78, 0.18, 3.93, [28.0, 11.51, 12.93], [22.06, 7.04, 8.4]),
        (2.05, 5.43, 0.19, 3.82, [27.06, 13.49, 13.0], [21.37, 8.17, 8.48]),
        (4.72, 5.03, 0.46, 3.03, [28.64, 11.72, 14.45], [22.57, 7.11, 9.4]),
        (3.18, 4.62, 0.21, 3.22, [28.9, 13.54, 11.53], [22.6, 8.19, 7.57]),
        (2.50, 4.08, 0.21, 2.96, [28.75, 11.8, 12.96], [22.49, 7.17, 8.49]),
        (8.58, 7.36, 0.49, 3.65, [28.01, 14.64, 14.34], [21.94, 8.95, 9.47]),
        (10.94, 4.16, 0.59, 2.51, [26.9, 14.62, 14.26, 14.48], [21.14, 9.03, 9.46, 11.14]),
        (3.24, 4.43, 0.14, 3.99, [27.33, 13.31, 12.85], [21.56, 8.25, 8.53]),
    ]
    w, r = _replayed(453.0, rows)
    assert w.changes == 0 and r.frames == 15


def _rescaled(rng, zoom=1.0, scale_jitter=0.06):
    """(extents, radii) of _scene's objects seen through a depth network that guesses its
    scale anew in every frame: the radii follow the zoom alone, the extents also that guess."""
    radii = _scene(rng, zoom)
    s = np.exp(rng.normal(0, scale_jitter))
    return {i: r * s for i, r in radii.items()}, radii


def test_a_depth_scale_that_changes_every_frame_leaves_the_image_radii_to_judge():
    """Extents that scatter by 6% with the depth's scale tell nothing; the objects' image radii
    still do. The focal step of test_a_focal_step_the_image_scale_does_not_follow_is_no_zoom
    restarts the window with extents alone and not with radii; the zoom of
    test_a_zoom_the_image_scale_shows_is_seen_at_once is seen at its second frame, as with
    clean extents (with these extents alone: at its seventh), and the window keeps its frames
    through it at the zoom the radii measure (1.222 for 1.22; the extents, scattered as they
    are, measure the same step within two of their standard errors)."""
    changes = {}
    for with_radii in (True, False):
        rng = np.random.default_rng(9)
        w = FocalWindow(WindowOptions(max_frames=30))
        for k in range(30):
            f = 600.0 * (1.2 if k >= 15 else 1.0) * np.exp(rng.normal(0, 0.005))
            ext, rad = _rescaled(rng)
            w.add(estimate(f, 0.005, std_rel_noise=0.005, extents=ext,
                           radii=rad if with_radii else None), k / 30)
        changes[with_radii] = w.changes
    assert changes == {True: 0, False: 1}
    assert _zoom_restarts(10, 40, lambda k, zoom, rng: _rescaled(rng, zoom)) == [(21, 22, 1.222)]
    assert _zoom_restarts(10, 40, lambda k, zoom, rng: _rescaled(rng, zoom)[0]) == [(26, 7)]


def test_a_zoom_while_the_camera_moves_is_seen_by_the_scale_that_moves_with_it():
    """The zoom of test_a_zoom_the_image_scale_shows_is_seen_at_once while the camera backs
    away by 15% (the radii grow by 6%, the extents by the zoom's 22%), and a dolly zoom (the
    radii held): the extents' scale lets the step stand, and the window restarts at the zoom
    as with a still camera. (When any scale that could tell vetoed a step, neither restarted in
    40 frames.) It does not keep its frames at the radii's step: the extents measure another."""
    def backing(share):
        def sizes(k, zoom, rng):
            away = share if k >= 20 else 1.0
            radii = _scene(rng, zoom / away)
            return {i: r * away for i, r in radii.items()}, radii
        return sizes

    assert _zoom_restarts(10, 40, backing(1.15)) == [(21, 2)]
    assert _zoom_restarts(10, 40, backing(1.22)) == [(21, 2)]


def _zoom_run(seed, zoom, n, before, after, jitter=0.01, with_radii=True):
    """A window over n frames with a zoom at frame 20: frames before and after it err by
    (bias, std_rel, std_rel_noise, scatter) and show _scene's objects (sizes scattering by
    ``jitter``) as extents and, ``with_radii``, radii. The window and its estimates."""
    rng = np.random.default_rng(seed)
    w = FocalWindow(WindowOptions(max_frames=30))
    out = []
    for k in range(n):
        z = zoom if k >= 20 else 1.0
        bias, std, noise, scatter = after if k >= 20 else before
        f = 600.0 * z * np.exp(bias + rng.normal(0, scatter))
        sizes = _scene(rng, z, jitter=jitter)
        out.append(w.add(estimate(f, std, std_rel_noise=noise, extents=sizes,
                                  radii=sizes if with_radii else None), k / 30))
    return w, out


def test_a_zoom_the_radii_measure_keeps_the_older_frames_at_the_new_focal():
    """Frames that scatter by 6% through a 22% zoom at frame 20, in 20 sequences: where the
    objects' image radii measure the zoom, the window keeps its older frames at the new focal
    length (the zoom taken as 1.2073-1.2276 here, the radii's and the focal lengths' steps
    pooled) and errs by 0.84% (median over frames 21-29), where a window restarted with the
    frames since the zoom errs by 2.27%; its std_rel still covers."""
    errors, covered, zooms = {True: [], False: []}, [], []
    frames = (0.0, 0.10, 0.01, 0.06)
    for with_radii in (True, False):
        for seed in range(20):
            _, rs = _zoom_run(seed, 1.22, 30, frames, frames, with_radii=with_radii)
            zooms += [r.zoom for r in rs if r.zoom is not None]
            for r in rs[21:]:
                error = abs(np.log(r.focal / (600.0 * 1.22)))
                errors[with_radii].append(error)
                covered.append(error <= 2 * r.std_rel)
    assert len(zooms) == 20 and max(abs(np.log(np.array(zooms) / 1.22))) < 0.015
    assert np.median(errors[True]) < 0.009 and np.median(errors[False]) > 0.02
    assert np.mean(covered) > 0.9


def test_precise_frames_measure_a_zoom_better_than_ragged_radii():
    """Frames as precise as sensor depth gives (0.1%) through a zoom of 0.8, with radii that
    scatter by 4% a frame, in 10 sequences: in the 9 whose radii can tell the zoom (the tenth
    restarts), the window keeps its frames at the zoom the focal lengths measure (within 0.3%;
    the radii alone measured 0.786-0.818) and errs by less than 0.3% after it. (Tuning sensor
    sequence 5107 at x0.8 was carried 7% off by its radii alone, and stayed 5% off for 13
    frames.)"""
    zooms, worst = [], 0.0
    frames = (0.0, 0.002, 0.001, 0.001)
    for seed in range(10):
        w, rs = _zoom_run(seed, 0.8, 26, frames, frames, jitter=0.04)
        zooms += [r.zoom for r in rs if r.zoom is not None]
        worst = max([worst] + [abs(np.log(r.focal / 480.0)) for r in rs[21:]])
        assert w.changes == 1
    assert len(zooms) == 9 and max(abs(np.log(np.array(zooms) / 0.8))) < 0.003
    assert worst < 0.003


def test_frames_carried_through_a_zoom_weigh_less_by_the_error_of_their_old_view():
    """Frames that err by -12% (std_rel 15%) before a 25% zoom and by -1% (4%) after it, whose
    radii measure the zoom: in the 5 of 10 sequences where the focal lengths' step agrees with
    the radii's, the window keeps its older frames, and five frames after the zoom errs by
    -3.0 to -4.6% (std_rel 6.4-7.2%, the last widened by its newest frame's disagreement): their
    budget beyond the newer frames' counts as noise. Taken at full weight, they held it at -9.5
    to -9.8% (std_rel 14.9%)."""
    carried = []
    for seed in range(10):
        w, rs = _zoom_run(seed, 1.25, 26, (-0.12, 0.15, 0.03, 0.03), (-0.01, 0.04, 0.03, 0.03))
        if len(w) == 26:
            carried.append((np.log(rs[-1].focal / 750.0), rs[-1].std_rel))
    assert len(carried) == 5
    assert all(-0.05 < e < -0.025 and s < 0.075 for e, s in carried), carried


def test_one_wild_image_scale_does_not_move_the_split_far():
    """The zoom of test_a_zoom_the_image_scale_shows_is_seen_at_once with the objects' extents
    of frame 21 (the second after the zoom) at the old scale: the window restarts at frame 22
    with the three frames since the zoom. (Splitting at the trailing run of new-scale frames,
    as 2cd06bf did, kept frame 22 alone.)"""
    restarts = _zoom_restarts(12, 30, lambda k, zoom, rng: _scene(rng, 1.0 if k == 21 else zoom))
    assert restarts == [(22, 3)]


def test_instance_ids_that_do_not_follow_the_objects_leave_zooms_to_the_focal_lengths():
    """A segmentation network that finds two to four of four objects of very different sizes
    and numbers them anew in every frame: the image scale scatters and tells nothing. Over 40
    sequences with a 20% zoom among frames with 3% noise, the window restarts exactly where it
    does without extents (36 of 40 within 5 frames of the zoom, 43 restarts; judged without
    asking whether the scale can tell a zoom, 29 of 40)."""

    def run(seed, with_extents):
        rng = np.random.default_rng(seed)
        w = FocalWindow(WindowOptions(max_frames=30))
        changed = []
        for k in range(60):
            zoom = 1.2 if k >= 30 else 1.0
            sizes = rng.permutation([120.0, 60.0, 30.0, 15.0])[:rng.integers(2, 5)]
            extents = {i + 1: e * zoom for i, e in enumerate(sizes)} if with_extents else None
            e = estimate(600.0 * zoom * np.exp(rng.normal(0, 0.03)), 0.03, extents=extents)
            if w.add(e, k / 30).changed:
                changed.append(k)
        return changed

    shuffled = [run(seed, True) for seed in range(40)]
    assert shuffled == [run(seed, False) for seed in range(40)]
    assert sum(bool(c) and 30 <= c[0] <= 35 for c in shuffled) == 36


def test_no_restart_on_static_sequences_with_outlier_frames():
    rng = np.random.default_rng(3)
    w = FocalWindow(WindowOptions(max_frames=30))
    for k, e in enumerate(frames(rng, 300)):
        if k % 17 == 0:
            e = estimate(e.focal * 1.4, e.std_rel)  # a lone wild frame
        w.add(e, k / 30)
    assert w.changes == 0


def test_two_wild_frames_among_four_newer_ones_are_no_step():
    """Sensor-like frames (0.1%) with two wrong frames (-20%, std_rel 3-4%) among the four
    newest: the midpoint of an even segment's two middle frames moved 10%, most frames did not
    (seed 5034 of the tuning sensor sequences restarted twice on this)."""
    rng = np.random.default_rng(5)
    w = FocalWindow(WindowOptions(max_frames=30))
    for k, e in enumerate(frames(rng, 12, sigma=0.001)):
        w.add(e, k / 30)
    for k, (f, s) in enumerate([(480.0, 0.04), (600.0, 0.002), (600.5, 0.002), (470.0, 0.03)]):
        w.add(estimate(f, s, std_rel_noise=s), 1 + k / 30)
    assert w.changes == 0


@pytest.mark.parametrize("noise", [0.10, 0.005])
def test_frames_that_err_as_much_as_they_say_are_no_step(noise):
    """Three frames at +14% that say std_rel 10% after tight frames (0.5%) are 1.4 of their own
    standard errors from the rest, not a zoom, whether that 10% is noise or a systematic budget
    the older frames do not share (tuning sensor sequences 5031 and 5033 restarted on such
    frames, judged by the frames' spread alone; with a floor of the frames' noise alone, 5031
    restarted twice)."""
    rng = np.random.default_rng(6)
    w = FocalWindow(WindowOptions(max_frames=30))
    for k, e in enumerate(frames(rng, 15, sigma=0.005)):
        w.add(e, k / 30)
    for k, f in enumerate([684.0, 690.0, 681.0]):
        w.add(estimate(f, 0.10, std_rel_noise=noise), 1 + k / 30)
    assert w.changes == 0


def test_image_size_change_starts_a_new_window():
    w = FocalWindow()
    for k in range(10):
        w.add(estimate(600.0), k / 30)
    r = w.add(estimate(300.0, size=(320, 240)), 1.0)
    assert r.changed and r.frames == 1 and r.focal == pytest.approx(300.0)


def test_a_frame_of_another_size_without_evidence_does_not_end_the_window():
    """As in fcop_node: one stray frame without a focal length is not added; the window keeps
    its frames and its focal (before, it emptied the window)."""
    w = FocalWindow()
    for k in range(10):
        w.add(estimate(600.0), k / 30)
    stray = FocalEstimate(None, (4.5, 4.5), (10, 10), reason="nothing")
    r = w.add(stray, 0.4)
    assert r.focal == pytest.approx(600.0) and r.frames == 10 and not r.changed


def test_estimates_without_std_rel_are_named_as_why_there_is_no_focal():
    """method="ransac", refine=False and the paper's method give no std_rel; the window weighs
    frames by it, so it reports none and says why."""
    w = FocalWindow()
    for k in range(12):
        r = w.add(estimate(600.0, std_rel=None), k / 30)
    assert r.focal is None and "12 of its frames have a focal but no usable std_rel" in r.reason
    w = FocalWindow(WindowOptions(max_frames=5))
    for k in range(12):
        w.add(estimate(600.0, std_rel=None) if k < 6 else empty_estimate(), k / 30)
    assert "no std_rel" not in w.current.reason  # they have left the window


def test_stamps_must_be_finite_numbers_that_do_not_go_back():
    w = FocalWindow(WindowOptions(max_age=1.0))
    w.add(estimate(600.0), 5.0)
    w.add(estimate(600.0), 5.0)  # the same instant is allowed
    with pytest.raises(ValueError, match="reset"):
        w.add(estimate(600.0), 4.9)
    with pytest.raises(ValueError, match="finite"):
        w.add(estimate(600.0), float("nan"))
    with pytest.raises(TypeError, match="seconds"):
        w.add(estimate(600.0), "6")
    with pytest.raises(TypeError, match="seconds"):
        w.add(estimate(600.0), True)  # a hostile trial: taken as 1.0 s before
    assert len(w) == 2
    w.reset()
    assert w.add(estimate(600.0), 0.0).frames == 1


def test_what_is_no_estimate_is_refused_by_name():
    """A new user's trial: add(None, t) failed with "'NoneType' object has no attribute
    'image_size'", a focal of "600" with numpy's "ufunc 'isfinite' not supported", and a
    negative std_rel was taken as its size. Each now names what is wrong."""
    w = FocalWindow()
    with pytest.raises(TypeError, match="must be a FocalEstimate"):
        w.add(None, 0.0)
    with pytest.raises(TypeError, match="focal must be a number or None, got '600'"):
        w.add(replace(estimate(600.0), focal="600"), 0.0)
    with pytest.raises(TypeError, match="std_rel must be a number or None"):
        w.add(replace(estimate(600.0), std_rel="0.01"), 0.0)
    with pytest.raises(ValueError, match="std_rel must be >= 0 or None, got -0.01"):
        w.add(replace(estimate(600.0), std_rel=-0.01), 0.0)
    assert len(w) == 0
    assert w.add(estimate(600.0), 0.0).frames == 1


def test_max_frames_max_age_and_reset():
    w = FocalWindow(WindowOptions(max_frames=5, max_age=0.25))
    for k in range(10):
        w.add(estimate(600.0), k * 0.1)
    assert len(w) == 3  # stamps 0.7, 0.8, 0.9 are within 0.25 s of 0.9
    w.reset()
    assert len(w) == 0 and w.current.focal is None


def test_invalid_settings_are_refused():
    with pytest.raises(ValueError):
        FocalWindow(WindowOptions(max_frames=0))
    with pytest.raises(ValueError):
        FocalWindow(WindowOptions(max_age=-1))
    with pytest.raises(ValueError):
        FocalWindow(WindowOptions(change_threshold=0))
    with pytest.raises(ValueError, match="min_frames"):  # it could never report
        FocalWindow(WindowOptions(max_frames=5, min_frames=6))
    with pytest.raises(TypeError, match="WindowOptions"):
        FocalWindow(30)


def test_wild_frames_are_judged_by_the_frames_own_spread():
    """Frames that err far less than their systematic budget says (sensor-like depth: 0.01%
    noise, 1% stated) must still lose a wild frame: judged against their stated 1%, a +0.5%
    frame would pass and pull the window 20 times further than the noise does."""
    rng = np.random.default_rng(4)
    w = FocalWindow(WindowOptions(max_frames=30))
    for k in range(30):
        e = rng.normal(0, 1e-4) + (0.005 if k % 10 == 3 else 0.0)
        r = w.add(estimate(600.0 * np.exp(e), 0.01, std_rel_noise=1e-4), k / 30)
    assert r.used == 27
    assert abs(np.log(r.focal / 600.0)) < 1e-4


def test_vectorised_medians_give_the_bits_of_the_loops_they_replace():
    """The window's NaN-skipping medians of its extent matrix equal np.nanmedian's bits, and
    the step at every split at once equals the step split by split, on 2000 random cases with
    ties and lines without a finite value (with the same outputs on 13,840 stored window
    updates, a script: only the cost changed, 0.89 -> 0.45 ms median per update)."""
    import warnings

    from fcop_ros.core.window import _difference, _differences, _nanmedian

    rng = np.random.default_rng(5)
    for _ in range(2000):
        r, c = rng.integers(1, 31), rng.integers(1, 8)
        a = np.round(rng.normal(size=(r, c)), int(rng.integers(1, 4)))  # ties
        a[rng.random((r, c)) < rng.uniform(0, 0.6)] = np.nan
        for axis in (0, 1):
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", RuntimeWarning)  # an all-NaN line
                want = np.nanmedian(a, axis=axis)
            np.testing.assert_array_equal(_nanmedian(a, axis), want)
        n = int(rng.integers(2, 31))
        k = int(rng.integers(1, n // 2 + 1))
        y = np.round(rng.normal(size=n), 1)
        cut = np.arange(k, n - k + 1)
        np.testing.assert_array_equal(_differences(y, cut), [_difference(y, c) for c in cut])


def test_a_frame_that_is_no_evidence_does_not_break_the_window():
    """A focal of NaN, 0 or below is refused where it is added (it broke every later update,
    a division by zero); a std_rel of 0, inf or 1e200 (object_tau=inf gave inf) is a frame
    without evidence; the good frames around them still make the estimate."""
    w = FocalWindow()
    for bad in (float("nan"), 0.0, -5.0):
        with pytest.raises(ValueError, match="focal must be finite and > 0"):
            w.add(estimate(bad, 0.01), 0.0)
    for k, s in enumerate((0.01, 0.0, np.inf, 1e200, 0.01, 0.01)):
        r = w.add(estimate(600.0 + k, s, std_rel_noise=s), float(k))
    assert r.used == 3 and abs(r.focal - 603.0) < 3.0 and np.isfinite(r.std_rel)


def _offset_frames(rng, n, repeating_share, true=(6.0, -4.0), focal=600.0):
    """Frame estimates of a camera whose principal point is ``true`` px off the assumed centre:
    each frame's objects tell the offset with information I (a data std of 3 px per axis), of
    which ``repeating_share`` is an error that repeats in every frame; each frame's focal length
    is corrected by its own offset, which the prior of 4.8 px shrinks towards none."""
    from fcop_ros.core.offsets import IntrinsicsEvidence, offset_posterior
    std, info, g = np.array([4.8, 3.6]), np.eye(2) / 9.0, np.array([1e-3, -5e-4])
    true = np.asarray(true)
    repeated = rng.normal(0, 3.0 * np.sqrt(repeating_share), 2)
    noise = 1e-4
    out = []
    for _ in range(n):
        seen = true + repeated + rng.normal(0, 3.0 * np.sqrt(1 - repeating_share), 2)
        delta, cov = offset_posterior(info, info @ seen, std)
        logf = np.log(focal) + g @ (true - delta) + rng.normal(0, noise)
        repeating = info / repeating_share if repeating_share > 0 else info * 1e12
        est = estimate(float(np.exp(logf)), float(np.sqrt(noise**2 + g @ cov @ g)),
                       std_rel_noise=noise)
        est.intrinsics_evidence = IntrinsicsEvidence(std, delta, cov, info,
                                                              info @ seen, repeating, g)
        out.append(est)
    return out


def _window_error(ests, focal=600.0, pooled=True):
    w = FocalWindow(WindowOptions(max_frames=30))
    for t, e in enumerate(ests):
        if not pooled:
            e = replace(e, intrinsics_evidence=None)
        we = w.add(e, float(t))
    return abs(np.log(we.focal / focal)), we.std_rel


def test_the_window_pools_the_principal_points_evidence_of_its_frames():
    """Frames whose objects' errors renew: 30 frames tell the offset as one frame of 30 times
    the information, so the prior's shrinkage, which every frame repeats, goes. Measured over
    20 windows: median |error| 0.053% pooled against 0.241% frame by frame (the data's own
    noise, 0.55 px of offset, is what is left), and 2 std_rel covered 19 of 20."""
    rng = np.random.default_rng(0)
    pooled, alone, cover = [], [], []
    for _ in range(20):
        ests = _offset_frames(rng, 30, repeating_share=0.0)
        err, std = _window_error(ests)
        pooled.append(err), cover.append(err <= 2 * std)
        alone.append(_window_error(ests, pooled=False)[0])
    assert np.median(pooled) < 0.3 * np.median(alone)
    assert np.mean(cover) >= 0.9


def test_an_offset_error_that_repeats_in_every_frame_is_not_averaged_away():
    """The same objects' repeating errors tell the offset no better in 30 frames than in one:
    over 40 windows the median |error| stays at 0.240% (0.243% frame by frame), the window's
    std_rel says so (median 0.28%, where counting the frames as independent would say 0.06%)
    and 2 std_rel covered 39 of 40."""
    rng = np.random.default_rng(1)
    cover, stds = [], []
    for _ in range(40):
        err, std = _window_error(_offset_frames(rng, 30, repeating_share=1.0))
        cover.append(err <= 2 * std), stds.append(std)
    assert np.mean(cover) >= 0.9
    assert np.median(stds) > 2e-3


def test_a_newest_frame_the_window_cannot_yet_call_a_zoom_widens_its_std_rel():
    """A zoom shows first in one frame, too few to tell it from an error: the window's focal
    is still the old one, and its std_rel says it may be (measured: 0.28% for 20 frames that
    agree within their 1%, 18.3% once a frame 20% longer follows (0.28% before this term), the
    log of the step less
    that frame's own variance; a frame that agrees leaves it at 0.27%)."""
    rng = np.random.default_rng(3)
    w = FocalWindow(WindowOptions(max_frames=30))
    for k, e in enumerate(frames(rng, 20, sigma=0.01)):
        settled = w.add(e, k / 30)
    assert settled.std_rel < 0.004
    zoomed = w.add(estimate(720.0, 0.01, std_rel_noise=0.01), 20 / 30)
    assert not zoomed.changed and abs(zoomed.focal / 600.0 - 1) < 0.01
    assert zoomed.std_rel > 0.17  # log(1.2) = 0.182, less the frame's own 1%: 2 std_rel cover
    agreeing = FocalWindow(WindowOptions(max_frames=30))
    for k, e in enumerate(frames(np.random.default_rng(3), 20, sigma=0.01)):
        agreeing.add(e, k / 30)
    assert agreeing.add(estimate(601.0, 0.01, std_rel_noise=0.01), 20 / 30).std_rel < 0.004
