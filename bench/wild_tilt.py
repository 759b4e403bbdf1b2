"""How the threshold of core/error_model.py's WILD_TILT was chosen, on the tuning model only.

    python bench/wild_tilt.py [--frames 200]

For each threshold (inf: no object left out of a frame's depth-field curvature), the same
tuning frames of the randomised world (seeds from 1000, as world_accuracy.py's single-frame
rows): how many frames the rule changes, their std_rel against no rule, and the coverage of
2 std_rel over all frames.
"""
from __future__ import annotations

import argparse

import numpy as np

from fcop_ros import estimate_focal
from fcop_ros.core import error_model
from fcop_ros.synthetic.world import world_frame


def run(frames, threshold):
    error_model.WILD_TILT = threshold
    return [estimate_focal(fr.depth, fr.nocs, fr.mask, seed=k, poses=False)
            for k, fr in enumerate(frames)]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--frames", type=int, default=200)
    args = ap.parse_args()
    kept = error_model.WILD_TILT
    print("| preset | threshold | frames changed | their std_rel / without the rule | "
          "coverage of 2 std_rel |")
    print("|---|---|---|---|---|")
    for preset in ("sensor", "predicted"):
        frames = [world_frame(preset, 1000 + s, "tuning") for s in range(args.frames)]
        base = run(frames, np.inf)
        for threshold in (np.inf, 3.0, kept, 10.0):
            ests = base if threshold == np.inf else run(frames, threshold)
            ratio = [e.std_rel / b.std_rel for e, b in zip(ests, base)
                     if e.focal is not None and b.focal is not None and e.std_rel != b.std_rel]
            cover = [abs(np.log(e.focal / fr.focal)) <= 2 * e.std_rel
                     for e, fr in zip(ests, frames) if e.focal is not None]
            span = (", ".join(f"{r:.2f}" for r in sorted(ratio)) or "-") if len(ratio) <= 5 else (
                f"{min(ratio):.2f}-{max(ratio):.2f}, median {np.median(ratio):.2f}")
            print(f"| {preset} | {threshold:g} | {len(ratio)} | {span} | "
                  f"{100 * np.mean(cover):.1f}% |")
    error_model.WILD_TILT = kept


if __name__ == "__main__":
    main()
