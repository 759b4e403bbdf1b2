"""A rectified image's residual radial distortion k1: its effect on f, which each object's
refit predicts (the fit moves far more than the distortion's magnification where the depth is
noisy), and the k1 that the objects' disagreement shows, by which the frame corrects f."""
from dataclasses import replace

import numpy as np

from fcop_ros import EstimatorOptions, estimate_focal
from fcop_ros.synthetic.world import (_LENS, WORLD_PRESETS, ErrorFamilies, _distorted,
                                     _undistort, lens_coefficients, world_frame, world_frames)


def test_the_lens_gradient_predicts_what_a_distortion_does_to_f():
    """Eight `sensor` frames without a lens, then taken through k1 = -0.01 and +0.01: the
    focal length moves by -0.03 to -1.43 per unit of k1 (measured; the magnification alone
    would be +0.01 to +0.12, as the frames' truth moves by a script: noisy depth lets the fit
    trade distance for f; measured with the estimate of k1 off), and the frame's gradient from
    the refits, in its evidence, is 0.9-1.7 times it (measured 0.91-1.69)."""
    fam = replace(WORLD_PRESETS["sensor"], lens=0.0)
    fixed = EstimatorOptions(lens_distortion_std=0.0)
    ratios = []
    for s in range(8):
        fr = world_frames(fam, 1000 + s, 1).frames[0]
        truth = world_frames(ErrorFamilies(), 1000 + s, 1).frames[0]
        logf = {}
        for k1 in (-0.01, 0.0, 0.01):
            seen = _distorted(fr, truth.mask, lambda x, y, k1=k1: _undistort(x, y, k1, 0.0))
            logf[k1] = np.log(estimate_focal(seen.depth, seen.nocs, seen.mask, seed=s,
                                             poses=False, options=fixed).focal)
        moved = (logf[0.01] - logf[-0.01]) / 0.02
        est = estimate_focal(fr.depth, fr.nocs, fr.mask, seed=s, poses=False)
        ratios.append(est.intrinsics_evidence.gradient[2] / moved)
    assert 0.8 <= min(ratios) and max(ratios) <= 1.9, ratios


def test_a_frame_of_objects_spread_over_the_image_tells_its_lens():
    """Five `sensor` tuning frames of four to six objects (seeds 1020, 1040, 1041, 1045, 1056,
    the bench's; lenses k1 -0.0060, -0.0093, -0.0069, +0.0084, -0.0099): the k1 their
    disagreement shows is within 0.0015 of the lens's (measured within 0.0013), and the focal
    length it corrects errs less than without the estimate in every one (measured
    0.48 -> 0.01%, 0.12 -> 0.06%, 0.28 -> 0.02%, 0.46 -> 0.09%, 0.58 -> 0.02%)."""
    off = EstimatorOptions(lens_distortion_std=0.0)
    for seed in (1020, 1040, 1041, 1045, 1056):
        fr = world_frame("sensor", seed)
        k1, _ = lens_coefficients(_LENS, seed)
        est = estimate_focal(fr.depth, fr.nocs, fr.mask, seed=seed - 1000, poses=False)
        without = estimate_focal(fr.depth, fr.nocs, fr.mask, seed=seed - 1000, poses=False,
                                 options=off)
        assert abs(est.lens_k1 - k1) <= 0.0015, (seed, est.lens_k1, k1)
        assert abs(np.log(est.focal / fr.focal)) < abs(np.log(without.focal / fr.focal)), seed


def test_one_object_cannot_tell_a_lens_and_pays_the_prior():
    """A frame of one object cannot tell k1 from its own focal length: k1 stays at 0 and the
    lens's part of std_rel is the prior's through the object's gradient."""
    fr = world_frames("sensor", 1001, 1, objects=1).frames[0]
    est = estimate_focal(fr.depth, fr.nocs, fr.mask, seed=1, poses=False)
    ev = est.intrinsics_evidence
    assert abs(est.lens_k1) < 1e-12
    np.testing.assert_allclose(est.std_rel_lens,
                               abs(ev.gradient[2]) * EstimatorOptions().lens_distortion_std,
                               rtol=1e-9)
