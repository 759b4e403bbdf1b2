"""The paper's point simulation (Sec. IV-A): random objects seen by random cameras.

NOCS points uniform in [-1, 1]^3, focal f ~ U[300, 1500] px, scale s ~ U[0.2, 1], a uniform
random rotation and a translation uniform in a ball of radius 2 m about (0, 0, 4) m. Image
points are exact projections, relative to the principal point.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation


@dataclass
class PointTrial:
    """One simulated object: x (N,2) px, d (N,) m, p (N,3) NOCS in [-1,1]^3, and the truth."""

    x: np.ndarray
    d: np.ndarray
    p: np.ndarray
    focal: float
    scale: float
    rotation: np.ndarray
    translation: np.ndarray


def random_ball(rng: np.random.Generator, n: int, radius: float) -> np.ndarray:
    """n points uniform in a ball of the given radius."""
    v = rng.normal(size=(n, 3))
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    return v * radius * rng.random(n)[:, None] ** (1 / 3)


def simulate_points(rng: np.random.Generator, n_points: int = 3, depth_noise: float = 0.0,
                    nocs_noise: float = 0.0) -> PointTrial:
    """One trial of the paper's simulation, optionally with bounded uniform noise
    (depth noise in metres, NOCS noise in NOCS units, each bounded in norm)."""
    f = rng.uniform(300, 1500)
    s = rng.uniform(0.2, 1.0)
    R = Rotation.random(random_state=rng).as_matrix()
    t = np.array([0.0, 0.0, 4.0]) + random_ball(rng, 1, 2.0)[0]
    p = rng.uniform(-1, 1, (n_points, 3))
    X = s * p @ R.T + t
    d = X[:, 2].copy()
    x = f * X[:, :2] / d[:, None]
    if depth_noise > 0:
        d = d + rng.uniform(-depth_noise, depth_noise, n_points)
    if nocs_noise > 0:
        p = p + random_ball(rng, n_points, nocs_noise)
    return PointTrial(x, d, p, f, s, R, t)


def simulate_triplet_batch(rng: np.random.Generator, count: int):
    """``count`` independent noise-free triplets, vectorised: x (T,3,2), d (T,3), p (T,3,3),
    focal (T,), scale (T,)."""
    f = rng.uniform(300, 1500, count)
    s = rng.uniform(0.2, 1.0, count)
    R = Rotation.random(count, random_state=rng).as_matrix()
    t = np.array([0.0, 0.0, 4.0]) + random_ball(rng, count, 2.0)
    p = rng.uniform(-1, 1, (count, 3, 3))
    X = s[:, None, None] * np.einsum("tij,tnj->tni", R, p) + t[:, None, :]
    d = X[..., 2]
    x = f[:, None, None] * X[..., :2] / d[..., None]
    return x, d, p, f, s
