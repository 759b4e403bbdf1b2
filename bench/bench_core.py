"""Speed of the core library: each figure beside its target and a reference from the same run.

    python bench/bench_core.py [--repeats 5] [--cores 1]      (make bench)

Runs pinned to ``--cores`` cores (default one, and OpenCV then uses one thread), and
prints the load average first: on a shared machine read the ratios, which hold, rather than
the absolute times. Figures:

- solve_triplets in M triplets/s (target >= 10 M/s) on 1e6 simulated triplets of distinct
  points and on 1e6 random triplets of 10,000 points (the estimator's pattern), next to a
  plain numpy pass that only gathers the pairs and forms their squared norms, and the numpy
  path (the fallback without numba) of the same call;
- interval stabbing of 1e6 votes (target <= 50 ms and <= 1.5x one np.sort of 2e6 floats):
  stab_equal_width (the estimator's relative mode) and interval_stabbing (any widths);
- estimate_focal on 640x480 frames with 5 objects, without poses (target 5 ms on one quiet
  core and <= 0.2x the plain numpy reference of correspondences + votes + stabbing of
  bench/world_accuracy.py) beside the package's own numpy path (the compiled kernels off) on
  the same frames, with poses, the pose stage alone, and a breakdown by stage;
- a 1000x1000 frame with 10,000 instances, and one sliding-window update with 30 frames.

Times of single operations are the best of repeats; frame times are, per frame, the median of
``--repeats`` runs, then the median (and 95th percentile) over the frames.
"""
from __future__ import annotations

import argparse
import os
import platform
import time
from dataclasses import replace

import cv2
import numpy as np
from world_accuracy import plain_reference  # bench/ is on the path of this script

from fcop_ros import (FocalWindow, WindowOptions, estimate_focal, estimate_poses,
                      interval_stabbing, solve_triplets)
from fcop_ros.core import EstimatorOptions, compiled
from fcop_ros.core.camera import image_centre
from fcop_ros.core.correspondences import extract_instances
from fcop_ros.core.object_fit import fit_objects
from fcop_ros.core.solver import object_votes, sample_triplets
from fcop_ros.core.stabbing import focal_intervals, stab_equal_width
from fcop_ros.synthetic import apply_noise, render_scene, simulate_triplet_batch


def best_of(fn, *args, repeat=7):
    """Smallest wall time of ``repeat`` runs of fn(*args) (the least disturbed on a shared
    machine)."""
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        fn(*args)
        times.append(time.perf_counter() - t)
    return min(times)


def frame_times(fn, frames, repeats):
    """Per frame the median of ``repeats`` runs of fn(frame, k), in ms."""
    out = np.zeros((repeats, len(frames)))
    for r in range(repeats):
        for k, fr in enumerate(frames):
            t = time.perf_counter()
            fn(fr, k)
            out[r, k] = time.perf_counter() - t
    return 1000 * np.median(out, axis=0)


def verdict(ok: bool) -> str:
    return "meets" if ok else "MISSES"


def pair_norms(P, tri):
    """The reference: gathering a triplet's three pairs and their squared norms, nothing solved."""
    return ((P[tri[:, [0, 1, 0]]] - P[tri[:, [1, 2, 2]]]) ** 2).sum(-1)


def triplets(rng):
    n = 1_000_000
    x, d, p, _, _ = simulate_triplet_batch(rng, n)
    X, D, P = x.reshape(-1, 2), d.reshape(-1), p.reshape(-1, 3)
    cases = {"1e6 triplets of distinct points": (X, D, P, np.arange(3 * n).reshape(n, 3)),
             "1e6 random triplets of 10,000 points": (X[:10_000], D[:10_000], P[:10_000],
                                                      sample_triplets(10_000, n, rng)),
             }
    for name, (X, D, P, tri) in cases.items():
        t = best_of(solve_triplets, X, D, P, tri, repeat=5)
        t_ref = best_of(pair_norms, P, tri, repeat=5)
        rate = n / t / 1e6
        print(f"solve_triplets, {name}: {rate:.1f} M/s ({1e9 * t / n:.0f} ns each; "
              f"target >= 10 M/s: {verdict(rate >= 10)}); plain pair gather+norm alone: "
              f"{n / t_ref / 1e6:.1f} M/s")
        if compiled.ENABLED:  # the numpy fallback, the same call with the kernels off
            compiled.ENABLED = False
            try:
                t_np = best_of(solve_triplets, X, D, P, tri, repeat=3)
            finally:
                compiled.ENABLED = True
            print(f"  numpy path (FCOP_NUMBA=0): {n / t_np / 1e6:.1f} M/s; compiled "
                  f"{t_np / t:.1f}x faster")


def stabbing(rng):
    for n in (100_000, 1_000_000):
        votes = np.exp(rng.normal(np.log(600), 0.2, n))
        lo, hi, _ = focal_intervals(votes, 0.05)
        centre, half = np.log(votes), np.log1p(0.05)
        t_eq = best_of(stab_equal_width, centre, half)
        t_gen = best_of(interval_stabbing, lo, hi)
        t_sort = best_of(np.sort, np.concatenate([lo, hi]))
        line = (f"stabbing {n:>9,d} votes: equal widths {1000 * t_eq:6.1f} ms "
                f"({t_eq / t_sort:.2f}x), any widths {1000 * t_gen:6.1f} ms "
                f"({t_gen / t_sort:.2f}x) "
                f"of np.sort of the 2n ends {1000 * t_sort:6.1f} ms")
        if n == 1_000_000:
            ok = 1000 * t_eq <= 50 and t_eq <= 1.5 * t_sort
            line += f"; target <= 50 ms and <= 1.5x: {verdict(ok)}"
        print(line)


def stages(frames, repeats):
    """Per-frame cost of the estimator's stages, called as estimate_focal calls them."""
    opt = EstimatorOptions()
    h, w = frames[0].depth.shape
    pp = image_centre(w, h)

    def extract(fr):
        return extract_instances(
            fr.depth, fr.nocs, fr.mask, pp, min_object_pixels=opt.min_object_pixels,
            erode_px=opt.erode_px, denoise_radius=opt.denoise_radius,
            outlier_sigma=opt.outlier_sigma, edge_sigma=opt.edge_sigma,
            max_pixels=opt.max_pixels, max_instances=opt.max_instances,
            rng=np.random.default_rng(0))
    inst = [extract(fr) for fr in frames]
    rng = np.random.default_rng(0)
    data = []
    for ins in inst:
        sizes = [len(i.d) for i in ins]
        offs = np.concatenate([[0], np.cumsum(sizes)[:-1]])
        tri = np.concatenate([sample_triplets(n, opt.triplets_per_object, rng) + o
                              for n, o in zip(sizes, offs)])
        data.append((np.concatenate([i.x for i in ins]), np.concatenate([i.d for i in ins]),
                     np.concatenate([i.p for i in ins]), tri))
    votes = [solve_triplets(*dd)[0] for dd in data]
    votes = [v[v > 0] for v in votes]
    parts = {
        "correspondences": frame_times(lambda fr, k: extract(fr), frames, repeats),
        "triplet votes": frame_times(lambda fr, k: solve_triplets(*data[k]), frames, repeats),
        "vote stage (draws + solve)": frame_times(lambda fr, k: object_votes(
            [i.x for i in inst[k]], [i.d for i in inst[k]], [i.p for i in inst[k]],
            opt.triplets_per_object, np.random.default_rng(k), opt.focal_range), frames, repeats),
        "stabbing": frame_times(lambda fr, k: stab_equal_width(np.log(votes[k]), np.log1p(0.05)),
                                frames, repeats),
        "per-object fit": frame_times(lambda fr, k: fit_objects(
            inst[k], 600.0, max_pixels=opt.fit_pixels, iterations=opt.fit_iterations,
            rng=np.random.default_rng(k)), frames, repeats),
        "pose stage (estimate_poses)": frame_times(lambda fr, k: estimate_poses(inst[k], 600.0),
                                                   frames, repeats),
    }
    print("  by stage (median ms per frame): "
          + ", ".join(f"{k} {np.median(v):.1f}" for k, v in parts.items()))


def frame_estimate(repeats):
    frames = [apply_noise(render_scene(np.random.default_rng(k), 5, 600.0), "moderate",
                          np.random.default_rng(k)) for k in range(20)]
    for fr in frames[:3]:
        estimate_focal(fr.depth, fr.nocs, fr.mask, seed=0)  # warm-up
    obj_px = np.mean([(fr.mask > 0).sum() for fr in frames])
    def no_poses_run():
        return frame_times(
            lambda fr, k: estimate_focal(fr.depth, fr.nocs, fr.mask, seed=k, poses=False),
            frames, repeats)

    no_poses = no_poses_run()
    # The node hands the estimator float32 images (msg_adapters): the same frames as it sees them.
    f32 = [(fr.depth.astype(np.float32), fr.nocs.astype(np.float32), fr.mask) for fr in frames]
    as_node = frame_times(lambda im, k: estimate_focal(*im, seed=k, poses=False), f32, repeats)
    # What the assumed principal point's term costs: the same frames with the centre given.
    given_pp = frame_times(lambda fr, k: estimate_focal(
        fr.depth, fr.nocs, fr.mask, seed=k, poses=False,
        principal_point=image_centre(fr.depth.shape[1], fr.depth.shape[0])),
        frames, repeats)
    numpy_path = None
    if compiled.ENABLED:  # the numpy fallback on the same frames, right after
        compiled.ENABLED = False
        try:
            numpy_path = no_poses_run()
        finally:
            compiled.ENABLED = True
    ref = frame_times(lambda fr, k: plain_reference(fr, np.random.default_rng(k)), frames,
                      max(1, repeats // 2))
    poses = frame_times(lambda fr, k: estimate_focal(fr.depth, fr.nocs, fr.mask, seed=k), frames,
                        repeats)
    depth, nocs = frames[0].depth, frames[0].nocs
    t_scan = 1000 * best_of(lambda: np.isfinite(depth).sum() + np.isfinite(nocs).sum())
    med, ratio = np.median(no_poses), np.median(no_poses) / np.median(ref)
    print(f"estimate_focal 640x480, 5 objects ({obj_px:,.0f} object pixels), without poses: "
          f"median {med:.1f} ms, p95 {np.percentile(no_poses, 95):.1f} ms "
          f"(target 5 ms on one quiet core: {verdict(med <= 5)})")
    print(f"  the same frames as float32 images (as the node passes them): median "
          f"{np.median(as_node):.1f} ms")
    print(f"  with the principal point given (no principal-point term, as with camera_info_in): "
          f"median {np.median(given_pp):.1f} ms")
    if numpy_path is not None:
        print(f"  numpy path (FCOP_NUMBA=0) on the same frames: median "
              f"{np.median(numpy_path):.1f} ms; compiled {med / np.median(numpy_path):.2f}x that")
    print(f"  plain numpy reference (correspondences + votes + stabbing, "
          f"bench/world_accuracy.py): median {np.median(ref):.1f} ms; ratio {ratio:.3f} "
          f"(target <= 0.2: {verdict(ratio <= 0.2)})")
    print(f"  with poses: median {np.median(poses):.1f} ms, "
          f"p95 {np.percentile(poses, 95):.1f} ms; one np.isfinite pass over depth+NOCS: "
          f"{t_scan:.2f} ms")
    stages(frames, repeats)
    return frames


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--repeats", type=int, default=5,
                    help="runs per frame (their median is taken)")
    ap.add_argument("--cores", type=int, default=1, help="cores to pin to (0: no pinning)")
    args = ap.parse_args()
    if args.cores > 0 and hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, set(sorted(os.sched_getaffinity(0))[: args.cores]))
        cv2.setNumThreads(1)
    pinned = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
          f"pinned to {pinned}; load average {os.getloadavg()[0]:.2f}; python "
          f"{platform.python_version()}, numpy {np.__version__}, opencv {cv2.__version__}")
    rng = np.random.default_rng(0)
    triplets(rng)
    stabbing(rng)
    frames = frame_estimate(args.repeats)

    # A mask of 10,000 instances (10x10 blocks over 1000x1000): only the largest max_instances
    # (64) are processed, so the cost follows the pixels, not the instances squared.
    n = 1000
    yy, xx = np.mgrid[0:n, 0:n]
    mask = (yy // 10 * 100 + xx // 10 + 1).astype(np.int32)
    depth = 1.0 + 0.0001 * xx + 0.0002 * yy
    nocs = np.stack([(xx % 10) / 10, (yy % 10) / 10, np.full((n, n), 0.5)], -1)
    t_many = best_of(lambda: estimate_focal(depth, nocs, mask, seed=0), repeat=3)
    print("estimate_focal 1000x1000, 10,000 instances of 100 px: "
          f"{1000 * t_many:.0f} ms (best of 3)")

    ests = [estimate_focal(fr.depth, fr.nocs, fr.mask, seed=k) for k, fr in enumerate(frames)]
    print(f"FocalWindow.add with 30 frames in the window: median {window_add_ms(ests):.2f} ms; "
          "the same estimates without their intrinsics evidence (no pooling): median "
          f"{window_add_ms([replace(e, intrinsics_evidence=None) for e in ests]):.2f} ms")


def window_add_ms(ests) -> float:
    """Median ms of FocalWindow.add with 30 frames of ``ests`` (cycled) in the window."""
    window = FocalWindow(WindowOptions(max_frames=30))
    for k in range(30):
        window.add(ests[k % len(ests)], k / 30)
    t = []
    for k in range(30, 60):
        s = time.perf_counter()
        window.add(ests[k % len(ests)], k / 30)
        t.append(time.perf_counter() - s)
    return 1000 * float(np.median(t))


if __name__ == "__main__":
    main()
