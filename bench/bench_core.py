"""Speed of the core library, each figure next to a plain numpy reference measured in the same run.

    python bench/bench_core.py            (make bench)

Prints: triplets solved per second (vs. a plain numpy pass over the same arrays), interval
stabbing for 1e5 and 1e6 votes (vs. np.sort of the 2n end points, its floor), the frame
estimate on 640x480 frames with 5 objects (median and 95th percentile, vs. one np.isfinite pass
over the image), a 1000x1000 frame with 10,000 instances, and one sliding-window update with
30 frames in the window.
"""
from __future__ import annotations

import os
import platform
import time

import numpy as np

from fcop_ros import FocalWindow, estimate_focal, interval_stabbing, solve_triplets
from fcop_ros.core.stabbing import focal_intervals
from fcop_ros.synthetic import apply_noise, render_scene, simulate_triplet_batch


def best_of(fn, repeat=7):
    """Smallest wall time of ``repeat`` runs (the least disturbed on a shared machine)."""
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return min(times)


def main() -> None:
    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
          f"python {platform.python_version()}, numpy {np.__version__}")
    rng = np.random.default_rng(0)

    n = 1_000_000
    x, d, p, _, _ = simulate_triplet_batch(rng, n)
    X, D, P = x.reshape(-1, 2), d.reshape(-1), p.reshape(-1, 3)
    tri = np.arange(3 * n).reshape(n, 3)
    t_solve = best_of(lambda: solve_triplets(X, D, P, tri), 3)
    # Reference: gathering the three pairs and forming their squared norms, nothing solved.
    t_ref = best_of(lambda: ((P[tri[:, [0, 1, 0]]] - P[tri[:, [1, 2, 2]]]) ** 2).sum(-1), 3)
    print(
        f"solve_triplets: {n / t_solve / 1e6:.2f} M triplets/s ({1e9 * t_solve / n:.0f} ns each); "
        f"reference pair gather+norm alone: {n / t_ref / 1e6:.2f} M/s"
    )

    for n in (100_000, 1_000_000):
        votes = np.exp(rng.normal(np.log(600), 0.2, n))
        lo, hi, _ = focal_intervals(votes, 0.05)
        t = best_of(lambda: interval_stabbing(lo, hi), 5)
        t_sort = best_of(lambda: np.sort(np.concatenate([lo, hi])), 5)
        print(
            f"interval_stabbing {n:>9,d} votes: {1000 * t:7.1f} ms  (np.sort of the 2n ends: "
            f"{1000 * t_sort:6.1f} ms)"
        )

    frames = [apply_noise(render_scene(np.random.default_rng(k), 5, 600.0), "moderate",
                          np.random.default_rng(k))
              for k in range(20)]
    for fr in frames[:3]:
        estimate_focal(fr.depth, fr.nocs, fr.mask, seed=0)  # warm-up
    times = []
    for k, fr in enumerate(frames):
        t = time.perf_counter()
        estimate_focal(fr.depth, fr.nocs, fr.mask, seed=k)
        times.append(time.perf_counter() - t)
    t_scan = best_of(
        lambda: np.isfinite(frames[0].depth).sum() + np.isfinite(frames[0].nocs).sum(), 7
    )
    obj_px = np.mean([(fr.mask > 0).sum() for fr in frames])
    print(
        f"estimate_focal 640x480, 5 objects ({obj_px:,.0f} object pixels): median "
        f"{1000 * np.median(times):.1f} ms, "
        f"p95 {1000 * np.percentile(times, 95):.1f} ms  (one np.isfinite pass over depth+NOCS: "
        f"{1000 * t_scan:.2f} ms)"
    )

    # A mask of 10,000 instances (10x10 blocks over 1000x1000): only the largest max_instances
    # (64) are processed, so the cost follows the pixels, not the instances squared.
    n = 1000
    yy, xx = np.mgrid[0:n, 0:n]
    mask = (yy // 10 * 100 + xx // 10 + 1).astype(np.int32)
    depth = 1.0 + 0.0001 * xx + 0.0002 * yy
    nocs = np.stack([(xx % 10) / 10, (yy % 10) / 10, np.full((n, n), 0.5)], -1)
    t_many = best_of(lambda: estimate_focal(depth, nocs, mask, seed=0), 3)
    print(
        f"estimate_focal 1000x1000, 10,000 instances of 100 px: {1000 * t_many:.0f} ms (best of 3)"
    )
    no_poses = [best_of(lambda: estimate_focal(fr.depth, fr.nocs, fr.mask, seed=0, poses=False), 1)
                for fr in frames]
    print(f"  without poses, 640x480, 5 objects: median {1000 * np.median(no_poses):.1f} ms")

    window = FocalWindow(max_frames=30)
    ests = [estimate_focal(fr.depth, fr.nocs, fr.mask, seed=k) for k, fr in enumerate(frames)]
    for k in range(30):
        window.add(ests[k % len(ests)], k / 30)
    t = []
    for k in range(30, 60):
        s = time.perf_counter()
        window.add(ests[k % len(ests)], k / 30)
        t.append(time.perf_counter() - s)
    print(f"FocalWindow.add with 30 frames in the window: median {1000 * np.median(t):.1f} ms")


if __name__ == "__main__":
    main()
