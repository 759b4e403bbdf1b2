"""The embedded default: a synthetic sequence through the estimator, focal estimate vs truth."""
from __future__ import annotations

import argparse
import time

import numpy as np

from .core import FocalWindow, estimate_focal
from .synthetic import apply_noise, render_scene


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--frames", type=int, default=30)
    ap.add_argument("--preset", default="moderate")
    ap.add_argument("--focal", type=float, default=600.0)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    window = FocalWindow()
    print(f"true focal {args.focal:.1f} px, noise preset '{args.preset}', {args.frames} frames of 640x480")
    t_est = []
    for k in range(args.frames):
        rng = np.random.default_rng(args.seed + k)
        frame = apply_noise(render_scene(rng, 5, args.focal), args.preset, rng)
        t0 = time.perf_counter()
        est = estimate_focal(frame.depth, frame.nocs, frame.mask, seed=args.seed + k)
        win = window.add(est, k / 30.0)
        t_est.append(time.perf_counter() - t0)
        fr = "none" if est.focal is None else f"{est.focal:7.1f}"
        wf = "none" if win.focal is None else f"{win.focal:7.1f} ({100 * (win.focal / args.focal - 1):+.2f}%)"
        print(f"frame {k:3d}: frame estimate {fr}  window {wf}  objects {len(est.objects)}")
    print(f"final: {window.current.focal:.1f} px vs true {args.focal:.1f} px; "
          f"median estimate time {1000 * np.median(t_est):.1f} ms")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
