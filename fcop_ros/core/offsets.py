"""The camera's assumed intrinsics, as offsets the objects' disagreement shows: an assumed
principal point's (dx, dy) px (:mod:`.principal_point`) and a rectified image's residual
radial distortion k1 (:mod:`.lens`).

Each object's log focal length moves with them by its own gradient, y_o = log f + g_o . delta
+ e_o, so the objects of a frame disagree in a way the offsets explain. A frame estimates delta
under a zero-mean prior and corrects its objects by it; a window pools its frames' evidence.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


def offset_information(y, var, grads) -> tuple[np.ndarray, np.ndarray]:
    """(I (m, m), b (m,)): what objects with log focal lengths ``y``, variances ``var`` and
    gradients ``grads`` (n, m) say of the offsets with the focal length free (the Schur
    complement of a least-squares fit of y = log f + grads . delta): the offsets' information
    and their data vector, so that delta = (P^-1 + I)^-1 b under a zero-mean prior of
    covariance P. Zero for one object, which cannot tell an offset from the focal length."""
    y, w, grads = np.asarray(y, float), 1.0 / np.asarray(var, float), np.asarray(grads, float)
    m = grads.shape[1]
    if y.size == 0:
        return np.zeros((m, m)), np.zeros(m)
    gw = grads.T @ w
    info = (grads * w[:, None]).T @ grads - np.outer(gw, gw) / w.sum()
    data = (grads * w[:, None]).T @ y - gw * float(w @ y) / w.sum()
    return info, data


def offset_posterior(info, data, prior_std) -> tuple[np.ndarray, np.ndarray]:
    """(delta (m,), its covariance (m, m)) from the information ``info`` and data vector
    ``data`` on the offsets and a zero-mean prior of ``prior_std`` per offset. An offset with no
    prior spread stays at 0."""
    std = np.asarray(prior_std, float)
    free = std > 0
    delta, cov = np.zeros(std.size), np.zeros((std.size, std.size))
    if not free.any():
        return delta, cov
    inv = np.linalg.inv(np.asarray(info, float)[np.ix_(free, free)]
                        + np.diag(1.0 / std[free] ** 2))
    delta[free] = inv @ np.asarray(data, float)[free]
    cov[np.ix_(free, free)] = inv
    return delta, cov


@dataclass(frozen=True)
class IntrinsicsEvidence:
    """What one frame's objects say of the offsets (dx px, dy px, k1) of the intrinsics it
    assumed, for a window to pool over its frames (one frame's objects fix them loosely; many
    frames' fix them better).

    prior_std: (3,), the prior's standard deviation per offset (0: given, not estimated).
    offset, covariance: the frame's own offsets and their covariance, by which its focal length
    was corrected. information, data: the objects' information on the offsets and its data
    vector (:func:`offset_information`) from their whole variances. repeating: the information
    from only the share of their variances that repeats while the same objects are in view (the
    systematic budget: shape mismatch, unseen depth error), which bounds what any number of
    frames of them can tell. gradient: (3,) d log f / d offset of the frame's focal length."""

    prior_std: np.ndarray
    offset: np.ndarray
    covariance: np.ndarray
    information: np.ndarray
    data: np.ndarray
    repeating: np.ndarray
    gradient: np.ndarray


def pooled_offset(evidence: list[IntrinsicsEvidence]) -> tuple[np.ndarray, np.ndarray]:
    """(delta (m,), covariance (m, m)): the offsets that frames' ``evidence`` (of one prior)
    tell together. Their errors that renew add up as independent frames' do (S, the sum of their
    information); those that repeat are told once (R, the frames' mean repeating information):
    the pooled data count as information (R^-1 + S^-1)^-1 = R (R + S)^-1 S, the frames' mean
    offset seen through a repeating error of R^-1 and a renewing one of S^-1.

    Where the frames disagree with the pooled offsets beyond their information (chi^2 per
    degree of freedom above 1, Birge's ratio), that information is overstated and is divided by
    the ratio: a frame whose objects claim too precise fits would otherwise set the window's
    offsets alone (on 40 tuning `sensor` sequences, one frame held 1000 times its neighbours'
    information on k1, and the window's coverage fell to 84%)."""
    std = evidence[-1].prior_std
    S = np.sum([e.information for e in evidence], axis=0)
    b = np.sum([e.data for e in evidence], axis=0)
    R = np.mean([e.repeating for e in evidence], axis=0)
    # pinv: frames of one object tell nothing (S = R = 0), frames of two only along a line.
    through = R @ np.linalg.pinv(R + S)
    info, data = through @ S, through @ b
    delta, _ = offset_posterior(0.5 * (info + info.T), data, std)
    ratio = _birge_ratio(evidence, delta)
    return offset_posterior(0.5 * (info + info.T) / ratio, data / ratio, std)


def _birge_ratio(evidence: list[IntrinsicsEvidence], delta: np.ndarray) -> float:
    """max(1, chi^2 / degrees of freedom) of the frames' data about the offsets ``delta``: each
    frame's residual b - I delta weighed by its own information, the degrees of freedom the
    ranks of their information less the offsets fitted."""
    chi2, dof = 0.0, -int(np.count_nonzero(evidence[-1].prior_std))
    for e in evidence:
        # One eigendecomposition for both: the residual weighed by the information's
        # pseudo-inverse (eigenvalues above 1e-10 of the largest, numpy's pinv with that
        # rcond) and the information's rank (numpy's matrix_rank tolerance).
        vals, vecs = np.linalg.eigh(e.information)
        size = np.abs(vals)
        top = size.max(initial=0.0)
        has = size > 1e-10 * top
        r = vecs[:, has].T @ (e.data - e.information @ delta)
        chi2 += float(r @ (r / vals[has]))
        dof += int(np.count_nonzero(size > top * vals.size * np.finfo(float).eps))
    return max(1.0, chi2 / dof) if dof > 0 else 1.0
