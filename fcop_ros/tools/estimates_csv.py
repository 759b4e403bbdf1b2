"""estimates.csv of fcop_replay: one row per published estimate, written and flushed as it comes,
each joined with the truth of its stamp when the bag has a truth topic."""

from __future__ import annotations

import csv
import math
from pathlib import Path

from .replay_base import ReplaySummary, output_head, writing

CSV_COLUMNS = ["stamp_ns", "focal", "cx", "cy", "support", "std_rel", "objects"]
TRUTH_COLUMNS = ["focal_true", "focal_error_pct"]
_HEADERS = {",".join(CSV_COLUMNS), ",".join(CSV_COLUMNS + TRUTH_COLUMNS)}


def not_an_estimates_csv(path: Path) -> str:
    """Why ``path`` is not an estimates.csv a replay wrote ('' when it is, or is empty or
    absent): a replay replaces its own table, never a user's file of that name (a user's
    o/estimates.csv was overwritten). Judged by its header, which every replay writes first."""
    first, why = output_head(path, 1024)
    if first is None:
        return why
    first = first.split(b"\n", 1)[0]
    header = first.rstrip(b"\r\n").decode("utf-8", "replace")
    if not first or header in _HEADERS:
        return ""
    return f"its first line is {header[:40]!r}"


class EstimatesCsv:
    """estimates.csv, one row per published estimate, written and flushed as it comes, so a
    failure later loses only what follows. With a truth topic a row waits for the truth of its
    stamp (a truth message may follow its frame's images in the bag): it is written once a
    truth message at or after its stamp has been read, or at the end."""

    def __init__(self, path: Path, with_truth: bool, summary: ReplaySummary):
        self.path, self.with_truth, self.summary = path, with_truth, summary
        self.cols = CSV_COLUMNS + (TRUTH_COLUMNS if with_truth else [])
        self.pending: list[dict] = []
        self.truth_stamps: list[int] = []
        self.truth_values: list[float] = []
        self.written = 0
        self.fh = None
        with writing(path):
            self.fh = open(path, "w", newline="")
            self._writer = csv.writer(self.fh)
            self._line(self.cols)

    def _line(self, values) -> None:
        self._writer.writerow(values)
        self.fh.flush()

    def truth(self, stamp: int, focal: float) -> None:
        import bisect

        i = bisect.bisect_left(self.truth_stamps, stamp)
        if i < len(self.truth_stamps) and self.truth_stamps[i] == stamp:
            self.truth_values[i] = focal
        else:
            self.truth_stamps.insert(i, stamp)
            self.truth_values.insert(i, focal)
        self._release()

    def add(self, row: dict) -> None:
        self.pending.append(row)
        self._release()

    def _attach(self, row: dict) -> None:
        """Truth of a row: the truth message of its stamp, else the latest one before it."""
        import bisect

        i = bisect.bisect_right(self.truth_stamps, row["stamp_ns"]) - 1
        if i < 0 or not 0 < self.truth_values[i] < math.inf:
            return  # an uncalibrated driver's all-zero K is no truth: the row goes without
        row["focal_true"] = float(self.truth_values[i])
        row["focal_error_pct"] = 100.0 * (row["focal"] / row["focal_true"] - 1.0)
        self.summary.errors_pct.append(abs(row["focal_error_pct"]))

    def _release(self, final: bool = False) -> None:
        while self.pending:
            row = self.pending[0]
            if (
                self.with_truth
                and not final
                and not (self.truth_stamps and self.truth_stamps[-1] >= row["stamp_ns"])
            ):
                return
            self.pending.pop(0)
            self._attach(row)
            with writing(self.path):
                self._line(
                    [
                        (
                            ""
                            if row.get(c) is None
                            else f"{row[c]:.6g}"
                            if c == "std_rel" and isinstance(row.get(c), float)
                            else f"{row[c]:.4f}"
                            if isinstance(row.get(c), float)
                            else row.get(c, "")
                        )
                        for c in self.cols
                    ]
                )
            self.written += 1
            self.summary.csv_rows = self.written

    def close(self, final: bool = True) -> None:
        try:
            if final:
                self._release(final=True)
        finally:
            if self.fh is not None:
                fh, self.fh = self.fh, None
                with writing(self.path):
                    fh.close()
