"""The frame's combination of its objects' focal lengths (fcop_ros.core.combine)."""
import numpy as np
import pytest

from fcop_ros.core.combine import combine_objects


def test_objects_weigh_by_their_noise_and_the_variance_keeps_the_budget():
    """Two objects with the same total variance: the one whose fit is less noisy counts 9:1 (its
    pixels carry nine times the information); the variance is that of this weighted mean with
    each object's whole variance and the prior spread between objects."""
    y, v, noise = np.log([600.0, 660.0]), np.array([0.04, 0.04]) ** 2, np.array([1e-4, 9e-4])
    c = combine_objects(y, v, noise, tau0=0.01, nu0=2.0)
    w = 1 / noise
    assert c.mean == pytest.approx(np.sum(w * y) / w.sum(), rel=1e-12)
    assert c.noise == pytest.approx(1 / w.sum(), rel=1e-12)
    assert c.var == pytest.approx(np.sum(w**2 * (v + c.tau2)) / w.sum() ** 2, rel=1e-12)
    # Never below what the total variances alone would give (their own optimal weights).
    assert c.var >= 1 / np.sum(1 / (v + c.tau2))


def test_noise_above_the_total_is_clipped_and_an_outlier_goes():
    """A noise variance above the object's total counts as the total; an object 30% off among
    four that agree within 1% is dropped, whatever its noise."""
    y = np.log([600.0, 603.0, 597.0, 601.0, 780.0])
    v = np.full(5, 0.01**2)
    noise = np.array([5e-5, 5e-5, 5e-5, 1.0, 1e-6])
    c = combine_objects(y, v, noise, tau0=0.005)
    assert c.used.tolist() == [True, True, True, True, False]
    w = 1 / np.minimum(noise, v)[:4]
    assert c.mean == pytest.approx(np.sum(w * y[:4]) / w.sum(), rel=1e-12)


def test_the_priors_share_is_whole_for_one_object_and_small_for_many():
    """One object pays the prior spread tau0^2 whole (nothing can contradict it); of five, the
    prior counts nu0 / (nu0 + 4) in tau^2, through the objects' weights."""
    one = combine_objects(np.log([600.0]), np.array([0.03 ** 2]), np.array([1e-4]), tau0=0.05)
    assert one.prior == pytest.approx(0.05 ** 2, rel=1e-12)
    assert one.var == pytest.approx(0.03 ** 2 + 0.05 ** 2, rel=1e-12)
    y = np.log([600.0, 606.0, 594.0, 603.0, 597.0])
    v, noise = np.full(5, 0.02 ** 2), np.array([1e-4, 2e-4, 1e-4, 3e-4, 1e-4])
    many = combine_objects(y, v, noise, tau0=0.05, nu0=2.0)
    w = 1 / noise
    assert many.prior == pytest.approx(np.sum(w ** 2) * (2 * 0.05 ** 2 / 6) / w.sum() ** 2,
                                       rel=1e-12)
    assert many.prior < 0.2 * one.prior and many.prior < many.var - many.noise
