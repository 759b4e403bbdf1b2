"""Umeyama similarity and the pose convention."""
import numpy as np
from scipy.spatial.transform import Rotation

from fcop_ros.core.pose import back_project, umeyama
from fcop_ros.synthetic import simulate_points


def test_umeyama_exact_on_noise_free_paper_simulation():
    rng = np.random.default_rng(8)
    worst = 0.0
    for _ in range(200):
        trial = simulate_points(rng, 50)
        pts = back_project(trial.x, trial.d, trial.focal)
        s, R, t = umeyama(trial.p, pts)
        worst = max(worst, abs(s / trial.scale - 1), np.abs(R - trial.rotation).max(),
                    np.abs(t - trial.translation).max())
    assert worst < 1e-6


def test_umeyama_batched_matches_single_and_reflection_is_fixed():
    rng = np.random.default_rng(9)
    src = rng.normal(size=(4, 20, 3))
    R = Rotation.random(4, random_state=rng).as_matrix()
    dst = 2.0 * np.einsum("bij,bnj->bni", R, src) + 1.0
    s, Rb, t = umeyama(src, dst)
    for b in range(4):
        s1, R1, t1 = umeyama(src[b], dst[b])
        assert abs(s1 - s[b]) < 1e-12 and np.allclose(R1, Rb[b]) and np.allclose(t1, t[b])
        assert abs(np.linalg.det(Rb[b]) - 1) < 1e-12
    # A mirrored target still yields a proper rotation.
    s, Rm, _ = umeyama(src[0], src[0] * [1, 1, -1])
    assert abs(np.linalg.det(Rm) - 1) < 1e-12
