"""Two hostile inputs the README quotes figures for, measured the way it describes them.

lost-channel: world frames of test/test_world_accuracy.py (seeds 7000 + 0..39, 320x240 and
640x480, `predicted` and `sensor`) with one NOCS channel made constant (0.5) on every object,
each channel in turn: how many give no focal and name the channel, and how far off the others
answer.

split-mask: `noisy_frame(seed, 'mild')` scenes whose mask is cut into 16 px tiles, each tile
its own instance id: the focal error and std_rel of each seed.

    python bench/hostile_inputs.py lost-channel
    python bench/hostile_inputs.py split-mask --seeds 0-11
"""
import argparse

import numpy as np

from fcop_ros import estimate_focal
from fcop_ros.synthetic import scenes

FIRST_SEED = 7000  # test/test_world_accuracy.py's


def lost_channel(seeds):
    total = named = 0
    answered = []
    for size in ((320, 240), (640, 480)):
        for preset in ("predicted", "sensor"):
            for s in seeds:
                fr = scenes.world_frame(preset, FIRST_SEED + s, size)
                has = (fr.nocs != 0).any(2)
                for channel in range(3):
                    flat = fr.nocs.copy()
                    flat[..., channel] = np.where(has, 0.5, 0.0)
                    est = estimate_focal(fr.depth, flat, fr.mask, seed=s, poses=False)
                    total += 1
                    if est.focal is None:
                        named += f"NOCS channel {channel} is 0.500 on every object" in est.reason
                    else:
                        answered.append((preset, size, s, channel,
                                         100 * (est.focal / fr.focal - 1), 100 * est.std_rel))
    print(f"{total} frames with one NOCS channel constant: "
          f"{total - len(answered)} give no focal ({named} name the channel), "
          f"{len(answered)} answer")
    for preset, size, s, channel, err, std in answered:
        print(f"  {preset} {size[0]}x{size[1]} seed {s} channel {channel}: "
              f"{err:+.1f}% at std_rel {std:.1f}%")


def split_mask(seeds, tile):
    for s in seeds:
        fr = scenes.noisy_frame(s, "mild")
        yy, xx = np.mgrid[0:fr.mask.shape[0], 0:fr.mask.shape[1]]
        tiles = (yy // tile) * (fr.mask.shape[1] // tile + 1) + xx // tile
        split = np.where(fr.mask > 0, fr.mask.astype(np.int64) * 100_000 + tiles, 0)
        whole = estimate_focal(fr.depth, fr.nocs, fr.mask, seed=s, poses=False)
        est = estimate_focal(fr.depth, fr.nocs, split, seed=s, poses=False)
        print(f"seed {s}: whole objects {_say(whole, fr.focal)}; "
              f"{tile} px tiles {_say(est, fr.focal)}")


def _say(est, truth):
    if est.focal is None:
        return f"no focal ({est.reason[:70]})"
    err = 100 * (est.focal / truth - 1)
    std = 100 * est.std_rel
    return f"{err:+.1f}% at std_rel {std:.1f}% ({abs(err) / std:.1f} std_rel off)"


def _seeds(text):
    lo, _, hi = text.partition("-")
    return range(int(lo), int(hi or lo) + 1)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("trial", choices=("lost-channel", "split-mask"))
    ap.add_argument("--seeds", type=_seeds, default=None, help="e.g. 0-39 (the default) or 3-11")
    ap.add_argument("--tile", type=int, default=16, help="split-mask tile size in px")
    a = ap.parse_args()
    if a.trial == "lost-channel":
        lost_channel(a.seeds or range(40))
    else:
        split_mask(a.seeds or range(12), a.tile)


if __name__ == "__main__":
    main()
