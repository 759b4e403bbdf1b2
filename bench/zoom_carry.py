"""The window through a zoom, keeping its older frames (as it does) or dropping them (as before).

    python bench/zoom_carry.py [--first-seed 6100] [--sequences 24]

On `predicted` zoom sequences of the tuning world (x1.25 and x0.8 at frame 20 of 40, seeds
from ``--first-seed``: the development set the carry was chosen on), each frame is estimated
once and the same estimates go through two windows: FocalWindow as it is, and one whose zoom
is never measured, so that every detected zoom drops the older frames. Per window: the
sequences within 5% for good in 15 frames after the zoom, the frames until then, and over
the frames 3-19 after the zoom the window's median |error| and its coverage of 2 std_rel.
"""
from __future__ import annotations

import argparse
from unittest import mock

import numpy as np

from fcop_ros import FocalWindow, WindowOptions, estimate_focal
from fcop_ros.core import window as window_module
from fcop_ros.synthetic.world import world_frames


def estimates(first_seed: int, sequences: int) -> list:
    """[(true focal, FocalEstimate) per frame] of every zoom sequence."""
    out = []
    for seed in range(first_seed, first_seed + sequences):
        for factor in (1.25, 0.8):
            seq = world_frames("predicted", seed, 40, "tuning", zoom_frame=20,
                               zoom_factor=factor)
            out.append([(fr.focal, estimate_focal(fr.depth, fr.nocs, fr.mask, seed=k,
                                                  poses=False))
                        for k, fr in enumerate(seq.frames)])
    return out


def score(runs: list) -> str:
    delays, errors, covered = [], [], []
    for frames in runs:
        w = FocalWindow(WindowOptions(max_frames=30))
        rows = [(t, w.add(est, k / 30)) for k, (t, est) in enumerate(frames)]
        after = rows[20:]
        bad = [i for i, (t, r) in enumerate(after)
               if r.focal is None or abs(np.log(r.focal / t)) > 0.05]
        delays.append(bad[-1] + 1 if bad else 0)
        for t, r in after[3:]:
            if r.focal is not None:
                errors.append(abs(np.log(r.focal / t)))
                covered.append(errors[-1] <= 2 * r.std_rel)
    return (f"{sum(d <= 15 for d in delays)} of {len(delays)} | {sorted(delays)} | "
            f"{100 * np.median(errors):.2f} | {100 * np.mean(covered):.1f}% |")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--first-seed", type=int, default=6100)
    ap.add_argument("--sequences", type=int, default=24, help="seeds (two zooms each)")
    args = ap.parse_args()
    runs = estimates(args.first_seed, args.sequences)
    print("| window | within 5% for good in 15 frames | frames until then | median abs error % "
          "(frames 3-19 after) | coverage of 2 std_rel |")
    print("|---|---|---|---|---|")
    print(f"| keeps its frames through a measured zoom | {score(runs)}")
    with mock.patch.object(window_module, "_zoom_step", lambda *args: None):
        print(f"| drops them at every zoom | {score(runs)}")


if __name__ == "__main__":
    main()
