"""The lens term of std_rel: a rectified image's residual radial distortion, whose effect on f
each object's refit predicts (the fit moves far more than the distortion's magnification where
the depth is noisy), and which never moves f itself."""
from dataclasses import replace

import numpy as np

from fcop_ros import EstimatorOptions, estimate_focal
from fcop_ros.synthetic.world import (WORLD_PRESETS, ErrorFamilies, _distorted, _undistort,
                                     world_frames)


def test_the_lens_term_predicts_what_a_distortion_does_to_f():
    """Eight `sensor` frames without a lens, then taken through k1 = -0.01 and +0.01: the
    focal length moves by -0.03 to -1.43 per unit of k1 (measured; the magnification alone
    would be +0.01 to +0.12, as the frames' truth moves by a script: noisy depth lets the fit
    trade distance for f), and
    ``std_rel_lens`` / ``lens_distortion_std`` of the undistorted frame, the refit's gradient,
    is 0.9-1.7 times it (measured 0.91-1.69)."""
    fam = replace(WORLD_PRESETS["sensor"], lens=0.0)
    std = EstimatorOptions().lens_distortion_std
    ratios = []
    for s in range(8):
        fr = world_frames(fam, 1000 + s, 1).frames[0]
        truth = world_frames(ErrorFamilies(), 1000 + s, 1).frames[0]
        logf = {}
        for k1 in (-0.01, 0.0, 0.01):
            seen = _distorted(fr, truth.mask, lambda x, y, k1=k1: _undistort(x, y, k1, 0.0))
            est = estimate_focal(seen.depth, seen.nocs, seen.mask, seed=s, poses=False)
            logf[k1] = (np.log(est.focal), est)
        moved = (logf[0.01][0] - logf[-0.01][0]) / 0.02
        ratios.append(logf[0.0][1].std_rel_lens / std / abs(moved))
    assert 0.8 <= min(ratios) and max(ratios) <= 1.9, ratios


def test_the_lens_term_widens_std_rel_and_never_moves_f():
    """Without the term (``lens_distortion_std`` 0) a frame's focal length is the same and its
    std_rel smaller by exactly the term (added in quadrature)."""
    fr = world_frames("sensor", 1001, 1).frames[0]
    on = estimate_focal(fr.depth, fr.nocs, fr.mask, seed=1, poses=False)
    off = estimate_focal(fr.depth, fr.nocs, fr.mask, seed=1, poses=False,
                         options=EstimatorOptions(lens_distortion_std=0.0))
    assert on.focal == off.focal and off.std_rel_lens == 0.0 and on.std_rel_lens > 1e-3
    np.testing.assert_allclose(on.std_rel**2 - off.std_rel**2, on.std_rel_lens**2, rtol=1e-9)
