"""Accuracy of the sliding window (what the node publishes) on synthetic camera sequences.

    python bench/window_accuracy.py [--seeds 4] [--frames 60]

Per noise preset and seed: one table-top scene seen by an orbiting camera, 640x480, f = 600 px.
Static: the window's error over frames 10..end, next to the single-frame errors of the same
frames. Zoom: f jumps to 750 px at the middle frame; frames until the window stays within 5% of the
new value (within 5% from then on), and its error from 10 frames after the zoom on.
"""
from __future__ import annotations

import argparse

import numpy as np

from fcop_ros import FocalWindow, estimate_focal
from fcop_ros.synthetic import PRESETS, SequenceSpec, camera_sequence


def run(spec: SequenceSpec, seed: int):
    window = FocalWindow(max_frames=30)
    rows = []
    for k, frame in camera_sequence(spec, seed):
        est = estimate_focal(frame.depth, frame.nocs, frame.mask, seed=k, poses=False)
        win = window.add(est, k / 30.0)
        rows.append((frame.focal, est.focal, win.focal))
    return rows


def err(a, b):
    return np.nan if a is None else 100 * abs(a / b - 1)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--seeds", type=int, default=4)
    ap.add_argument("--frames", type=int, default=60)
    args = ap.parse_args()
    print(f"{args.seeds} sequences of {args.frames} frames per preset; |focal error| in % (median / p90)\n")
    print("| preset | single frame (static) | window (static) | zoom: frames until within 5% for good | window after zoom |")
    print("|---|---|---|---|---|")
    half = args.frames // 2
    for preset in PRESETS:
        single, win, delay, after = [], [], [], []
        for seed in range(args.seeds):
            rows = run(SequenceSpec(args.frames, focal=600.0, preset=preset), seed)
            single += [err(f, t) for t, f, _ in rows[10:]]
            win += [err(w, t) for t, _, w in rows[10:]]
            rows = run(SequenceSpec(args.frames, focal=600.0, zoom_frame=half, zoom_focal=750.0, preset=preset),
                       100 + seed)
            e = [err(w, t) for t, _, w in rows[half:]]
            within = [i for i in range(len(e)) if all(x < 5.0 for x in e[i:])]
            delay.append(within[0] if within else np.nan)
            after += e[10:]
        q = lambda v: f"{np.nanmedian(v):.2f} / {np.nanpercentile(v, 90):.2f}"  # noqa: E731
        print(f"| {preset} | {q(single)} | {q(win)} | {np.nanmedian(delay):.0f} (max {np.nanmax(delay):.0f}) | "
              f"{q(after)} |", flush=True)


if __name__ == "__main__":
    main()
