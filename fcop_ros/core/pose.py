"""Similarity (scale, rotation, translation) between NOCS points and back-projected pixels.

Pose convention of fcop_ros, in the camera optical frame (x right, y down, z forward):

    depth * K^-1 [u, v, 1]^T = rotation @ (scale * (nocs - 0.5)) + translation

so the object frame is the NOCS frame centred at its bounding-box centre, ``scale`` is the
metric length (metres) of one NOCS unit (the bounding-box diagonal in the NOCS convention).
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
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


def robust_umeyama(nocs: np.ndarray, points: np.ndarray, iterations: int = 3, k: float = 3.0,
                   floor_rel: float = 1e-4, init: np.ndarray | None = None):
    """Umeyama fit with iterative rejection of residuals above k robust sigmas.

    nocs (N,3) in [0,1], points (N,3) camera-frame metres, init an optional starting inlier mask.
    Returns (scale, R, t, inlier mask, residuals) where the pose is fitted on the returned
    inliers. The threshold never drops below ``floor_rel`` times the fitted scale so that
    noise-free data keeps all its points.
    """
    src = np.asarray(nocs, dtype=np.float64) - 0.5
    inl = np.ones(len(src), dtype=bool) if init is None else init.copy()
    for it in range(max(1, iterations)):
        scale, R, t = umeyama(src[inl], points[inl])
        scale = float(scale)
        diff = points - (src @ (scale * R).T + t)
        res = np.sqrt(np.einsum("ij,ij->i", diff, diff))
        if it == iterations - 1:
            break
        med = np.median(res[inl]) if inl.any() else 0.0
        thr = max(k * 1.4826 * med, floor_rel * abs(scale), 1e-12)
        new = res <= thr
        if new.sum() < 3 or np.array_equal(new, inl):
            break
        inl = new
    return float(scale), R, t, inl, res


def refine_pose_reprojection(x: np.ndarray, nocs: np.ndarray, focal: float, scale: float, R: np.ndarray,
                             t: np.ndarray, max_points: int = 300):
    """Refine rotation and translation by minimising the reprojection error (OpenCV's iterative
    PnP from the given pose), keeping the metric scale.

    The 3D fit puts depth noise into the rotation; in the image the pixel positions are exact and
    only the NOCS noise is left. x (N,2) px from the principal point, nocs (N,3): inliers only,
    thinned to ``max_points``. Returns (R, t); the input pose when the refinement fails or moves
    implausibly far (more than 30 degrees)."""
    step = max(1, len(x) // max_points)
    obj = np.ascontiguousarray(scale * (np.asarray(nocs, dtype=np.float64)[::step] - 0.5))
    img = np.ascontiguousarray(np.asarray(x, dtype=np.float64)[::step])  # OpenCV wants contiguous rows
    if len(obj) < 6 or not scale > 0:
        return R, t
    K = np.array([[focal, 0.0, 0.0], [0.0, focal, 0.0], [0.0, 0.0, 1.0]])
    rvec, _ = cv2.Rodrigues(np.asarray(R, dtype=np.float64))
    tvec = np.asarray(t, dtype=np.float64).reshape(3, 1).copy()
    ok, rvec, tvec = cv2.solvePnP(obj, img, K, None, rvec, tvec, useExtrinsicGuess=True, flags=cv2.SOLVEPNP_ITERATIVE)
    if not ok or not (np.isfinite(rvec).all() and np.isfinite(tvec).all()):
        return R, t
    R2, _ = cv2.Rodrigues(rvec)
    if rotation_angle_deg(R2, R) > 30.0 or tvec[2, 0] <= 0:
        return R, t
    return R2, tvec.ravel()


def rotation_angle_deg(Ra: np.ndarray, Rb: np.ndarray) -> float:
    """Geodesic angle between two rotations in degrees, from ||Ra - Rb||_F = 2 sqrt(2) sin(angle/2):
    accurate for tiny angles too, unlike arccos of the trace."""
    s = np.linalg.norm(np.asarray(Ra) - np.asarray(Rb)) / (2.0 * np.sqrt(2.0))
    return float(np.degrees(2.0 * np.arcsin(np.clip(s, 0.0, 1.0))))
