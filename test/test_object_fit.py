"""The per-object fit under noise in its regressor, the NOCS (fcop_ros.core.object_fit and
correspondences.calibrated_nocs): noise in the NOCS shrinks the fitted similarity along the
object's thin axis, the line of sight, as any errors-in-variables regression does, and so
lengthens f; the regression calibration undoes that for the fit without the depth tilt."""
import dataclasses

import numpy as np
import pytest

from fcop_ros.core.correspondences import calibrated_nocs, extract_instances
from fcop_ros.core.object_fit import fit_objects
from fcop_ros.synthetic.world import ErrorFamilies, world_frame

FIRST_SEED = 7900
SIGMA = 0.02  # NOCS noise added to the fit's input, per coordinate


@pytest.fixture(scope="module")
def clean_objects():
    """The instances of 30 error-free world frames, with their true focal lengths."""
    out = []
    for s in range(30):
        fr = world_frame(ErrorFamilies(), FIRST_SEED + s)
        inst = extract_instances(fr.depth, fr.nocs, fr.mask, rng=np.random.default_rng(s))
        out.append((fr.focal, inst))
    return out


def _object_errors(clean_objects, calibrate, depth_tilt):
    """Each object's own focal error (%, log) with Gaussian noise of SIGMA added to its NOCS,
    fitted from the true focal length as the start."""
    rng = np.random.default_rng(1)
    errors = []
    for focal, inst in clean_objects:
        noisy = [dataclasses.replace(i, p=i.p + rng.normal(0, SIGMA, i.p.shape),
                                     var_p=np.full(len(i.d), SIGMA ** 2)) for i in inst]
        if calibrate:
            noisy = [calibrated_nocs(i) for i in noisy]
        fits = fit_objects(noisy, focal, max_pixels=300, depth_tilt=depth_tilt,
                           rng=np.random.default_rng(2))
        errors.extend(100 * np.log(fits.focal[fits.ok] / focal))
    return np.array(errors)


def test_noisy_nocs_lengthen_f_unless_calibrated(clean_objects):
    """Without the depth tilt, NOCS noise of 0.02 lengthens each object's f (signed median
    measured +2.68% over 92 objects) and the calibrated NOCS leave it unbiased (+0.02%; on 150
    frames, 504 objects: +3.16% and +0.07 +- 0.10%)."""
    raw = _object_errors(clean_objects, calibrate=False, depth_tilt=False)
    calibrated = _object_errors(clean_objects, calibrate=True, depth_tilt=False)
    assert raw.size >= 80
    assert np.median(raw) > 2.0
    assert abs(np.median(calibrated)) < 0.5


def test_the_depth_tilt_leaves_a_lean_the_calibration_does_not_reach(clean_objects):
    """With the depth tilt (as shipped) the calibrated fit still leans long: its clean
    regressor, the image position, takes up part of the depth along the line of sight, so the
    noisy NOCS are left less of it to explain than the calibration allows for. Measured +0.40%
    over 92 objects, +4.1% uncalibrated (on 150 frames: +0.09 / +0.28 / +0.82% at NOCS noise
    0.005 / 0.01 / 0.02, second order in the noise). At the noise left after denoising in
    `predicted` frames (median 0.0015, 90th percentile 0.0048 per coordinate) that is below
    0.1%. Documented in docs/BENCHMARKS.md (the bias section); this test notices if it
    changes."""
    calibrated = _object_errors(clean_objects, calibrate=True, depth_tilt=True)
    assert 0.2 < np.median(calibrated) < 1.5
