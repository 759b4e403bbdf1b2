"""The principal point's offset from the objects' disagreement, and each object's gradient of
log f by it (fcop_ros.core.principal_point), without ROS."""
import numpy as np

from fcop_ros import EstimatorOptions
from fcop_ros.core.correspondences import extract_instances
from fcop_ros.core.object_fit import fit_objects
from fcop_ros.core.offsets import offset_information, offset_posterior
from fcop_ros.core.principal_point import focal_gradients
from fcop_ros.synthetic.scenes import clean_frame


def principal_point_offset(y, var, grads, pp_std):
    return offset_posterior(*offset_information(y, var, grads), pp_std)


def test_the_offset_that_explains_the_objects_is_found_and_one_object_pays_the_prior():
    rng = np.random.default_rng(0)
    grads = rng.normal(0, 1e-3, (6, 2))  # log f per px, as objects spread over an image
    delta = np.array([4.0, -3.0])
    y = np.log(600.0) + grads @ delta
    var = np.full(6, 1e-8)
    got, cov = principal_point_offset(y, var, grads, (5.0, 5.0))
    assert np.allclose(got, delta, atol=0.05) and np.all(np.sqrt(np.diag(cov)) < 0.1)
    # One object cannot tell an offset from the focal length: nothing moves, the prior stays.
    got, cov = principal_point_offset(y[:1], var[:1], grads[:1], (5.0, 2.0))
    assert np.allclose(got, 0) and np.allclose(cov, np.diag([25.0, 4.0]))
    # An axis without prior spread is not estimated.
    got, cov = principal_point_offset(y, var, grads, (5.0, 0.0))
    assert got[1] == 0 and cov[1, 1] == 0 and cov[0, 0] > 0


def test_gradients_are_the_refits_at_a_moved_principal_point():
    """Each object's gradient (a secant over one standard deviation, 6 px, from the fit it is
    given) predicts its fit's focal length at a principal point moved by 2 px either way: the
    worst object's miss measured at 27% of the largest object's move along x (either way) and
    4-6% along y (the fit's response is not quite linear), 5 objects."""
    fr = clean_frame(3)
    opt = EstimatorOptions()
    inst = extract_instances(fr.depth, fr.nocs, fr.mask, rng=np.random.default_rng(0))

    def logf(shift):
        moved = [type(i)(**{**i.__dict__, "x": i.x - np.asarray(shift)}) for i in inst]
        return np.log(fit_objects(moved, 600.0, max_pixels=opt.fit_pixels,
                                  iterations=opt.fit_iterations,
                                  rng=np.random.default_rng(1)).focal)
    base = logf((0.0, 0.0))
    g = focal_gradients(inst, 600.0, 1, (6.0, 6.0), opt, base)
    assert np.all(g != 0)
    for shift in ((2.0, 0.0), (-2.0, 0.0), (0.0, 2.0), (0.0, -2.0)):
        move = logf(shift) - base
        assert np.abs(move - g @ np.array(shift)).max() <= 0.35 * np.abs(move).max()


def test_a_frame_hands_its_offsets_evidence_to_the_window():
    """The evidence a frame carries is the offsets (dx, dy, k1) it corrected by, from
    information the objects' repeating errors alone bound (more of it than all their errors
    give); where the principal point is given, the lens's k1 alone, and none where neither is
    estimated."""
    from fcop_ros import EstimatorOptions, estimate_focal
    fr = clean_frame(3)
    est = estimate_focal(fr.depth, fr.nocs, fr.mask, seed=0, poses=False)
    ev = est.intrinsics_evidence
    assert np.allclose(ev.offset, [*est.principal_point_offset, est.lens_k1])
    assert np.all(np.linalg.eigvalsh(ev.repeating - ev.information) > -1e-12)
    pp, g = ev.covariance[:2, :2], ev.gradient[:2]
    assert np.isclose(g @ pp @ g, est.std_rel_principal_point ** 2)
    assert np.isclose(ev.gradient[2] ** 2 * ev.covariance[2, 2], est.std_rel_lens ** 2)
    given = estimate_focal(fr.depth, fr.nocs, fr.mask, seed=0, poses=False,
                           principal_point=(319.5, 239.5))
    assert given.principal_point_offset is None and given.lens_k1 is not None
    assert np.array_equal(given.intrinsics_evidence.offset[:2], [0.0, 0.0])
    neither = estimate_focal(fr.depth, fr.nocs, fr.mask, seed=0, poses=False,
                             principal_point=(319.5, 239.5),
                             options=EstimatorOptions(lens_distortion_std=0.0))
    assert neither.intrinsics_evidence is None and neither.lens_k1 is None
