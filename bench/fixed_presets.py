"""The figures of docs/BENCHMARKS.md's "The older fixed presets" table: on the 40 frames
(seeds 0..39) that test/test_estimator.py's regression test checks, the median and 90th
percentile focal error, the median rotation error and the median translation error (% of the
distance) of each preset, with the test's own error function.

    python bench/fixed_presets.py
"""
import argparse
import os
import sys
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def main():
    argparse.ArgumentParser(description=__doc__,
                            formatter_class=argparse.RawDescriptionHelpFormatter).parse_args()
    sys.path.insert(0, os.path.join(ROOT, "test"))
    from test_estimator import _errors

    t = time.perf_counter()
    print("| preset | median / p90 focal error | median rotation error "
          "| median translation error (% of distance) |")
    print("|---|---|---|---|")
    for preset in ("mild", "moderate", "harsh"):
        focal, rot, trans = _errors(preset, range(40))
        lost = int(np.isnan(focal).sum())
        missing = f" ({lost} without a focal)" if lost else ""
        med, p90 = np.nanmedian(focal), np.nanpercentile(focal, 90)
        print(f"| {preset} | {med:.2f} / {p90:.2f}%{missing} "
              f"| {np.median(rot):.2f}° | {np.median(trans):.1f}% |", flush=True)
    print(f"({time.perf_counter() - t:.0f} s)")


if __name__ == "__main__":
    main()
