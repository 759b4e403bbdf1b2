"""Similarity (scale, rotation, translation) between NOCS points and back-projected pixels.

Pose convention of fcop_ros, in the camera optical frame (x right, y down, z forward):

    depth * K^-1 [u, v, 1]^T = rotation @ (scale * (nocs - 0.5)) + translation

so the object frame is the NOCS frame centred at its bounding-box centre, ``scale`` is the
metric length (metres) of one NOCS unit (the bounding-box diagonal in the NOCS convention).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


def back_project(x: np.ndarray, d: np.ndarray, focal: float) -> np.ndarray:
    """Camera-frame points (N,3) in metres from image points x (N,2, px from the principal
    point), z-depth d (N,) and the focal length in pixels."""
    return np.column_stack([d * x[:, 0] / focal, d * x[:, 1] / focal, d])


def umeyama(src: np.ndarray, dst: np.ndarray, weights: np.ndarray | None = None):
    """Least-squares similarity dst ~ scale * R @ src + t (Umeyama 1991), batched.

    src, dst: (..., N, 3); weights: optional (..., N) non-negative (e.g. an inlier mask).
    Returns (scale (...), R (..., 3, 3), t (..., 3)). Degenerate inputs give scale 0.
    """
    src = np.asarray(src, dtype=np.float64)
    dst = np.asarray(dst, dtype=np.float64)
    if weights is None:
        wn = np.full(src.shape[:-1], 1.0 / max(src.shape[-2], 1))
    else:
        w = np.asarray(weights, dtype=np.float64)
        wsum = w.sum(-1, keepdims=True)
        wn = w / np.where(wsum > 0, wsum, 1.0)
    # Weighted means and products as matrix products: BLAS, much faster than reductions over
    # an (N, 3) axis (this is the hot path of the robust fits).
    wrow = wn[..., None, :]
    mu_s = (wrow @ src)[..., 0, :]
    mu_d = (wrow @ dst)[..., 0, :]
    sc = src - mu_s[..., None, :]
    dc = dst - mu_d[..., None, :]
    if weights is None:
        cov = np.swapaxes(dc, -1, -2) @ sc / src.shape[-2]
    else:
        cov = np.swapaxes(dc * wn[..., None], -1, -2) @ sc
    var_s = (wrow @ (sc * sc))[..., 0, :].sum(-1)
    U, S, Vt = np.linalg.svd(cov)
    sign = np.sign(np.linalg.det(U) * np.linalg.det(Vt))
    sign = np.where(sign == 0, 1.0, sign)
    fix = np.ones(S.shape)
    fix[..., 2] = sign
    R = (U * fix[..., None, :]) @ Vt
    with np.errstate(divide="ignore", invalid="ignore"):
        scale = np.where(var_s > 0, (S * fix).sum(-1) / np.where(var_s > 0, var_s, 1.0), 0.0)
    t = mu_d - scale[..., None] * (R @ mu_s[..., None])[..., 0]
    return scale, R, t


@dataclass
class ObjectPose:
    """Pose of one instance (see the module docstring for the convention).

    instance_id: the mask value; rotation (3,3), translation (3,) metres, scale metres per NOCS
    unit; inlier_ratio: share of the instance's used pixels within the robust fit's threshold;
    rms: root mean square residual of the inliers in metres; pixels: pixels used.
    """

    instance_id: int
    rotation: np.ndarray
    translation: np.ndarray
    scale: float
    inlier_ratio: float
    rms: float
    pixels: int


def rotation_angle_deg(Ra: np.ndarray, Rb: np.ndarray) -> float:
    """Geodesic angle between two rotations in degrees, from
    ||Ra - Rb||_F = 2 sqrt(2) sin(angle/2): accurate for tiny angles too, unlike arccos of the
    trace."""
    s = np.linalg.norm(np.asarray(Ra) - np.asarray(Rb)) / (2.0 * np.sqrt(2.0))
    return float(np.degrees(2.0 * np.arcsin(np.clip(s, 0.0, 1.0))))
