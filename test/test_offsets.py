"""Pooling the intrinsics' offsets over a window's frames: frames that agree are told as their
information says, frames that disagree beyond it count for less (Birge's ratio)."""
import numpy as np

from fcop_ros.core.offsets import IntrinsicsEvidence, offset_posterior, pooled_offset

PRIOR = np.array([0.0, 0.0, 0.01])  # k1 alone, as where the principal point is given


def frame(k1: float, information: float) -> IntrinsicsEvidence:
    """A frame whose objects say k1 with ``information`` and repeat none of their errors."""
    info = np.diag([0.0, 0.0, information])
    data = info @ np.array([0.0, 0.0, k1])
    delta, cov = offset_posterior(info, data, PRIOR)
    return IntrinsicsEvidence(PRIOR, delta, cov, info, data, 1e9 * np.eye(3),
                              np.array([0.0, 0.0, -1.0]))


def test_frames_that_agree_are_pooled_as_their_information_says():
    """Ten frames saying k1 = 0.004 with an information of 1e4 each: the pooled k1 is the
    posterior of their summed information and the prior, no wider."""
    delta, cov = pooled_offset([frame(0.004, 1e4) for _ in range(10)])
    want = 1.0 / (1e5 * (1 - 1e-4) + 1e4)  # R (R + S)^-1 S with R = 1e9 and the prior's 1e4
    np.testing.assert_allclose(cov[2, 2], want, rtol=1e-3)
    np.testing.assert_allclose(delta[2], 0.004 * 1e5 * want, rtol=1e-3)


def test_frames_that_disagree_beyond_their_information_count_for_less():
    """Ten frames alternating k1 = 0.004 +- 0.05 with a standard error of 0.01 each: about 5
    standard errors from the pooled k1, chi^2 of 250 on 9 degrees of freedom, so their summed
    information counts 27.8 times less (the prior's does not), where without the ratio the
    pooled k1 would claim a standard error of 0.003."""
    frames = [frame(0.004 + (0.05 if t % 2 else -0.05), 1e4) for t in range(10)]
    _, cov = pooled_offset(frames)
    ratio = 1e5 / (1.0 / cov[2, 2] - 1e4)
    assert 26 <= ratio <= 30, ratio
