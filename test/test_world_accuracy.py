"""The estimator on the randomised world: no bias from zero-mean errors, an honest std_rel,
refusal of NOCS that only look like evidence, reflection invariance, the focal range, and a
frame with 10,000 instances. Numbers in the comments were measured on these seeds."""
import time
from dataclasses import replace

import numpy as np
import pytest

from fcop_ros import EstimatorOptions, FocalWindow, WindowOptions, estimate_focal
from fcop_ros.synthetic import scenes
from fcop_ros.synthetic.world import WORLD_PRESETS, ZERO_MEAN_FAMILIES, world_frame, world_frames

FIRST_SEED = 7000  # not the tuning seeds (1000..) nor the held-out ones (900000..)


def frame(preset, seed, size=None):
    return scenes.world_frame(preset, FIRST_SEED + seed, size)


def signed_errors(preset, n):
    err, cover = [], []
    for s in range(n):
        fr = frame(preset, s)
        est = estimate_focal(fr.depth, fr.nocs, fr.mask, seed=s, poses=False)
        if est.focal is not None:
            e = np.log(est.focal / fr.focal)
            err.append(e)
            cover.append(abs(e) <= 2 * est.std_rel)
    return np.array(err), np.array(cover)


# Signed median focal error (%) of each zero-mean mechanism alone (strength drawn up to its base
# bound), 24 frames: measured field -0.00, relief +0.00, offset -0.02, depth_pixel +0.00,
# nocs_pixel +0.01, nocs_field -0.16, shape -0.12 (-0.11 and -0.07 with object_tau 0.005;
# field +0.00, relief -0.15, offset -0.07, depth_pixel -0.00, nocs_pixel -0.01, nocs_field
# -0.21, shape -0.18 before objects were weighted by their noise; relief -0.43, shape -0.17
# while the objects' prior spread ignored their lean on depth). (Per-pixel NOCS noise gave
# +0.56% before the NOCS were regression-calibrated for the noise left after denoising:
# errors in the fit's regressor.)
@pytest.mark.parametrize("family", ZERO_MEAN_FAMILIES)
def test_no_bias_from_a_zero_mean_mechanism(family):
    err, _ = signed_errors(f"only_{family}", 24)
    assert err.size >= 22
    assert abs(np.median(err)) <= 0.005


# Full presets: sensor (120 frames) median |e| 0.006%, signed -0.00%, coverage 91.7% (its first
# 40: 87.5%; 95.0% while a misfit the depth made counted as a shape error); predicted
# (200 frames, at the recalibrated gain 0.55 of 25 Nov 2026) 198 answered (the others refused:
# one object explained 84.0% by its NOCS, a frame of 4.6% consensus), median |e| 3.38%, signed
# +0.30%, coverage 96.5%; at gain 0.4, all 200 answered, 2.36%, +0.51%, 96.5% (2.38%,
# +0.48%, 89.5% with object_tau 0.005, before the prior spread was the one multi-object frames
# show). Before objects were weighted by their noise: 0.016%, -0.00%, 90.0% and 2.95%, +0.91%,
# 87.0% (sensor coverage 97.5% while the objects' prior spread ignored that exact NOCS leave f to
# the pixels, not the depths). A median of 200 frames scatters by about 0.3%
# (docs/BENCHMARKS.md has the preset's bias over 2000).
@pytest.mark.parametrize("preset,frames,answered,cover_min",
                         [("sensor", 120, 120, 0.85), ("predicted", 200, 198, 0.85)])
def test_full_presets_unbiased_and_std_rel_covers(preset, frames, answered, cover_min):
    err, cover = signed_errors(preset, frames)
    assert err.size >= answered
    assert abs(np.median(err)) <= 0.01
    assert cover_min <= cover.mean() <= 0.98


def test_window_averages_on_moving_camera():
    """Eight orbiting 320x240 sequences of the predicted preset (window of 30, frames 5..29
    scored): measured single-frame median 7.03%, window 4.10% (ratio 0.58), window coverage
    100%, no restart, at the `predicted` preset's gain 0.55 (25 Nov 2026); at gain 0.4,
    single-frame median 4.41%, window 2.71% (ratio 0.61; 4.33% and 0.62
    with object_tau 0.005), window coverage 100%
    (above the issue's 98%: on these small, harsh frames the window keeps more of the frames'
    systematic budget than the truth needs), no restart. (Before objects and frames were
    weighted by their noise: 4.61%, 2.07%, 0.45. 40 such sequences, seeds 7500-7539, a script:
    4.55%, 2.73%, 0.60 before, 4.13%, 2.47%, 0.60 after; eight were a lucky draw.)"""
    single, win, cover, restarts = [], [], [], 0
    for q in range(8):
        seq = world_frames("predicted", FIRST_SEED + 500 + q, 30, size=(320, 240))
        w = FocalWindow(WindowOptions(max_frames=30))
        for k, fr in enumerate(seq.frames):
            est = estimate_focal(fr.depth, fr.nocs, fr.mask, seed=k, poses=False)
            r = w.add(est, k / 30)
            restarts += r.changed
            if k >= 5 and est.focal is not None and r.focal is not None:
                single.append(abs(np.log(est.focal / fr.focal)))
                win.append(abs(np.log(r.focal / fr.focal)))
                cover.append(win[-1] <= 2 * r.std_rel)
    assert restarts == 0
    assert np.median(win) <= 0.65 * np.median(single)
    assert np.mean(cover) >= 0.85


def test_zoom_on_the_world_short_of_the_aim():
    """Eight zoom sequences of the predicted preset (seeds 7600-7603, x1.25 and x0.8 at frame 20
    of 40, window of 30): frames until the window is within 5% of the new focal length for
    good, counted from the zoom (20: never). Measured 20, 11, 1, 1, 1, 1, 20, 8, eight changes
    and eight carried, since the `predicted` preset's gain went from 0.4 to 0.55 (25 Nov 2026;
    the two that never settle are the x1.25 zooms whose own frames err by 27.5% and 10.4%
    median after it); 2, 4, 1, 7, 1, 1, 20, 3, eight changes
    and eight carried, since the world's lens (25 Nov 2026); 20, 4, 6, 2, 1, 1, 20, 3, seven
    changes and five carried (the same without the principal point's term), since the world's
    principal point left the image centre; before, 20, 20, 1, 1, 1, 1, 20, 1 and seven
    changes detected (six at frame 21, one at 30): the objects' extents show the zoom at its
    second frame, and at six of the seven the window keeps its older frames at the zoom the
    radii measure (0.765-0.800 for 0.8, 1.249-1.269 for 1.25). Restarting instead (until this
    round): 20, 20, 1, 1, 1, 1, 20, 11. With the frames' focal lengths alone (f350ff8): 20, 20,
    20, 11, 1, 1, 20, 15 and three changes; when their whole std_rel floored a step (until
    1be3974): 20, 20, 20, 11, 20, 10, 20, 15 and two. Short of the issue's aim (15 frames): in
    three sequences the new focal's frames themselves err by 9-17% (median), which neither a
    restart nor the older frames mend."""
    delays, changes, carried = [], 0, 0
    for seed in range(FIRST_SEED + 600, FIRST_SEED + 604):
        for zoom in (1.25, 0.8):
            seq = world_frames("predicted", seed, 40, zoom_frame=20, zoom_factor=zoom)
            w = FocalWindow(WindowOptions(max_frames=30))
            bad = []
            for k, fr in enumerate(seq.frames):
                est = estimate_focal(fr.depth, fr.nocs, fr.mask, seed=k, poses=False)
                r = w.add(est, k / 30)
                changes += r.changed
                carried += r.zoom is not None
                if k >= 20 and (r.focal is None or abs(np.log(r.focal / fr.focal)) > 0.05):
                    bad.append(k - 20)
            delays.append(bad[-1] + 1 if bad else 0)
    assert sum(d <= 15 for d in delays) >= 6 and max(d for d in delays if d < 20) <= 11
    assert changes >= 7 and carried >= 7


def _garbage(fr, kind, rng):
    nocs = fr.nocs.copy()
    obj = fr.mask > 0
    if kind == "random":
        nocs[obj] = rng.random((int(obj.sum()), 3))
    else:  # the NOCS of the frame's object pixels, shuffled among them
        flat = nocs.reshape(-1, 3)
        idx = np.flatnonzero(obj.ravel())
        flat[idx] = flat[rng.permutation(idx)]
    return nocs


@pytest.mark.parametrize("kind", ["random", "shuffled"])
def test_nocs_that_only_look_like_evidence_give_no_focal(kind):
    """Measured: 0 of 8 frames answered, each with the reason below; every refused object
    (39 random, 34 shuffled) is named as noise, where most read 'degenerate fit' or 'too small
    a piece of the category's shape' before."""
    for s in range(8):
        fr = frame("predicted", s)
        est = estimate_focal(fr.depth, _garbage(fr, kind, np.random.default_rng(s)),
                             fr.mask, seed=s)
        assert est.focal is None and est.std_rel is None and est.objects == []
        assert "NOCS explain" in est.reason or "consensus" in est.reason
        assert all("noise, not a shape" in why for why in est.rejected.values())


def test_nocs_with_a_constant_channel_give_no_focal():
    """A NOCS network whose channel dies (or an image that loses one) flattens every object's
    NOCS onto a plane; the depth still shows solids. Before, 19 of 30 such frames answered, at
    -34 to -91%, most beyond 2 std_rel; with only objects that passed the other checks raising
    the question, 3 of these 24 frames still answered (std_rel 18-161%) and a user's 120 frames
    11, some with std_rel 6-11% at 40-90% off. Measured on these 24 frames with the x, y and z
    channel constant in turn (all of which answer with their NOCS intact): none answers, and
    all 72 name the channel. (At the `predicted` preset's gain 0.55, two frames answered,
    -185% at std_rel 12.6% and -10% at 43%, until a channel constant over two or more objects
    refused the frame even where no object read flat: seed 7's one good object, seen edge-on,
    was 0.1955 solid, under the flat test's 0.2.)"""
    named = 0
    for s in range(24):
        fr = frame("predicted", s)
        has = (fr.nocs != 0).any(2)
        assert estimate_focal(fr.depth, fr.nocs, fr.mask, seed=s, poses=False).focal
        for channel in range(3):
            flat = fr.nocs.copy()
            flat[..., channel] = np.where(has, 0.5, 0.0)
            est = estimate_focal(fr.depth, flat, fr.mask, seed=s, poses=False)
            assert est.focal is None
            named += f"NOCS channel {channel} is 0.500 on every object" in est.reason
    assert named >= 70


# Frames with a lost channel refused before any object read flat (too little consensus among
# the votes, or no object that passed the fit's other checks), at 320x240: their reasons did not
# name the channel. Of the 480 frames of seeds 0-39 at both sizes, `predicted` and `sensor`, with
# each channel constant in turn, 457 named it before and 476 now; the 4 others answer (-62% to
# +80%, std_rel 19-121%; `python bench/hostile_inputs.py lost-channel`, 24 Nov 2026): no object
# of theirs is solid enough in view to show the flat NOCS. Since the `sensor` preset's lens (25
# Nov 2026) its seed 31 with channel 2 flat is one of those that answer (-81%, std_rel 15%).
@pytest.mark.parametrize("preset, seed, channel", [
    ("predicted", 5, 0), ("predicted", 27, 2), ("predicted", 33, 0), ("sensor", 4, 1),
    ("sensor", 22, 0)])
def test_a_frame_refused_early_with_a_lost_channel_names_it(preset, seed, channel):
    fr = frame(preset, seed, (320, 240))
    flat = fr.nocs.copy()
    flat[..., channel] = np.where((fr.nocs != 0).any(2), 0.5, 0.0)
    est = estimate_focal(fr.depth, flat, fr.mask, seed=seed, poses=False)
    assert est.focal is None
    assert f"NOCS channel {channel} is 0.500 on every object" in est.reason


def test_one_object_s_flat_nocs_refuse_that_object_not_the_frame():
    """A network that fails on one instance (its NOCS flat, the others right): the frame answers
    from the others. Measured on these 10 frames, the largest object's z channel flattened: 9
    answer, within -5.6..+2.1% (the same frames intact: -8.5..+29.8%); the eighth had no other
    object its NOCS explain (at the `predicted` preset's gain 0.55, 25 Nov 2026; at gain 0.4,
    9 within -5.3..+10.5%, intact -3.7..+8.1%). (Before the world's principal point left the
    image centre: 9, within
    -3.7..+8.1%, intact -3.1..+5.0%. The fourth frame's -5.3% is -1.4% without the principal
    point's term: of its two objects, one moves 5% in f per pixel of the principal point, so the
    frame follows the other.)"""
    answered = []
    for s in range(10):
        fr = frame("predicted", s)
        ids, counts = np.unique(fr.mask[fr.mask > 0], return_counts=True)
        largest = ids[np.argmax(counts)]
        nocs = fr.nocs.copy()
        nocs[..., 2] = np.where(fr.mask == largest, 0.5, nocs[..., 2])
        est = estimate_focal(fr.depth, nocs, fr.mask, seed=s, poses=False)
        assert largest in est.rejected
        if est.focal is not None:
            answered.append(abs(np.log(est.focal / fr.focal)))
    assert len(answered) >= 8 and max(answered) < 0.12


def test_reflections_and_axis_permutations_leave_the_focal_unchanged():
    """The distance constraint is invariant to any orthogonal map of the NOCS, and so is the
    estimate: a mirrored axis, a BGR image read as RGB (an odd permutation) and an even permutation
    give the same focal length. Mirrored objects are reported and get no pose; the even
    permutation is a rotation, not a mirror."""
    for s in range(4):
        fr = frame("predicted", s, (640, 480))
        base = estimate_focal(fr.depth, fr.nocs, fr.mask, seed=s)
        assert base.focal is not None and base.mirrored == []
        obj = fr.mask > 0
        flipped = fr.nocs.copy()
        flipped[obj, 2] = 1.0 - flipped[obj, 2]
        for nocs, mirror in ((flipped, True), (fr.nocs[..., ::-1], True),
                             (fr.nocs[..., [1, 2, 0]], False)):
            est = estimate_focal(fr.depth, np.ascontiguousarray(nocs), fr.mask, seed=s)
            # up to rounding (measured 3e-9)
            assert est.focal == pytest.approx(base.focal, rel=1e-7)
            if mirror:
                # A symmetric object's reflection is also a rotation of it: only the others show.
                assert est.mirrored
                assert not set(p.instance_id for p in est.objects) & set(est.mirrored)
                assert all(np.linalg.det(p.rotation) > 0 for p in est.objects)
            else:
                assert est.mirrored == []


def test_focal_range_bounds_every_result():
    fr = frame("predicted", 1, (640, 480))
    est = estimate_focal(fr.depth, fr.nocs, fr.mask, seed=0)
    assert est.focal is not None
    for lo, hi in ((1.2 * fr.focal, 3 * fr.focal), (0.2 * fr.focal, 0.8 * fr.focal)):
        out = estimate_focal(fr.depth, fr.nocs, fr.mask, seed=0,
                             options=EstimatorOptions(focal_range=(lo, hi)))
        assert (
            out.focal is None
            and "focal_range" in out.reason
            or out.focal is not None
            and lo <= out.focal <= hi
        )


def test_ten_thousand_instances_are_answered_with_linear_work():
    """A 1000x1000 mask of 10x10 blocks (10,000 instances, each a tilted plane with NOCS): only
    the largest max_instances are processed, the rest counted. Measured 0.2 s (vs. unfinished
    after 580 s before the cap)."""
    n = 1000
    yy, xx = np.mgrid[0:n, 0:n]
    mask = (yy // 10 * 100 + xx // 10 + 1).astype(np.int32)
    depth = 1.0 + 0.0001 * xx + 0.0002 * yy
    nocs = np.stack([(xx % 10) / 10, (yy % 10) / 10, np.full((n, n), 0.5)], -1)
    t = time.perf_counter()
    opt = EstimatorOptions(min_object_pixels=50, max_instances=64)
    est = estimate_focal(depth, nocs, mask, options=opt, seed=0)
    elapsed = time.perf_counter() - t
    assert est.instances_skipped == 10_000 - 64
    assert est.focal is None or est.std_rel is not None
    assert elapsed < 60  # a generous ceiling against the quadratic behaviour, not a speed test


def test_an_assumed_principal_point_is_estimated_from_the_objects_and_its_doubt_reported():
    """Tuning-world `sensor` frames (seeds 7000-7059), whose principal points lie up to 2% of
    the image off its centre (rms 0.67% per axis), estimated at the centre as the node does
    without camera_info_in; without the preset's lens (since 25 Nov 2026), whose term would
    cover what this one is for. Without the principal point's term (principal_point_std 0):
    measured median |e| 0.141%, coverage of 2 std_rel 75%. With it (the default 0.75%): the
    objects' disagreement moves the principal point and f with it, 0.062% and 93% (0.072% and
    95% with central differences, before 93164a6). Given the true principal point: 0.0045% and
    no principal-point term at all (0.016% where the lens's k1 is estimated too, in this world
    without one)."""
    def run(options=None, given=False):
        err, cover, parts = [], [], []
        for s in range(60):
            fr = world_frame(pinhole, FIRST_SEED + s)
            est = estimate_focal(fr.depth, fr.nocs, fr.mask,
                                 fr.principal_point if given else None, options, seed=s,
                                 poses=False)
            err.append(abs(np.log(est.focal / fr.focal)))
            cover.append(err[-1] <= 2 * est.std_rel)
            parts.append(est.std_rel_principal_point)
        return np.median(err), np.mean(cover), np.array(parts)

    pinhole = replace(WORLD_PRESETS["sensor"], lens=0.0)
    e0, c0, p0 = run(EstimatorOptions(principal_point_std=0.0, lens_distortion_std=0.0))
    e1, c1, p1 = run(EstimatorOptions(lens_distortion_std=0.0))
    e2, _, p2 = run(EstimatorOptions(lens_distortion_std=0.0), given=True)
    assert np.all(p0 == 0) and np.all(p2 == 0) and np.all(p1 > 0)
    assert c0 < 0.8 and 0.9 <= c1 <= 0.98
    assert e1 < 0.7 * e0 and e2 < 0.1 * e1
