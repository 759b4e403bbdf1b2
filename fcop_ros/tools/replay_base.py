"""What fcop_replay's parts share: the errors that set the exit code, the guard that turns a
failed write into an OutputError, the checks that a bag has the topics asked for and messages on
them, and the summary of an offline run (which the CSV, the report and the command line fill
and read)."""

from __future__ import annotations

import sqlite3
from contextlib import contextmanager
from dataclasses import dataclass, field

import numpy as np

from sensor_msgs.msg import CameraInfo, Image

from ..ros.topics import type_name
from .bagio import BagSource

IMAGE_TYPE = type_name(Image)
INFO_TYPE = type_name(CameraInfo)


class ReplayError(RuntimeError):
    """A replay that cannot run as asked (bad bag, topic, type, encoding or parameter): exit 2."""


class OutputError(ReplayError):
    """An output that cannot be written (read-only, not a directory, disk full): exit 4."""


def check_out_dir(out_dir) -> None:
    """ReplayError for an empty --out: ``Path("")`` is the current directory, which a user who
    left the option's value out did not choose."""
    if not str(out_dir):
        raise ReplayError("--out is empty: give the output directory ('.' for this one)")


@contextmanager
def writing(what):
    """Turn a failed write of an output into OutputError naming the output and the reason."""
    try:
        yield
    except (OSError, sqlite3.Error) as exc:
        reason = getattr(exc, "strerror", None) or str(exc) or type(exc).__name__
        raise OutputError(f"cannot write {what}: {reason}") from exc


def output_head(path, size: int):
    """The first ``size`` bytes of an output file a replay is about to replace, to judge whether
    it wrote it: (bytes, '') for a regular file, (None, '') when nothing stored can be lost (the
    path is absent, or a device or a pipe such as a link to /dev/null), (None, why) when it
    cannot be judged (a directory, unreadable)."""
    if not path.exists():
        return None, ""
    if path.is_dir():
        return None, "a directory"
    if not path.is_file():
        return None, ""
    try:
        with open(path, "rb") as fh:
            return fh.read(size), ""
    except OSError as exc:
        return None, f"unreadable: {exc.strerror or exc}"


def check_topics(source: BagSource, wanted: dict) -> None:
    """wanted: {role: (topic, expected type)}; raise ReplayError naming what the bag has
    instead."""
    for role, (topic, msgtype) in wanted.items():
        if topic not in source.topics:
            raise ReplayError(
                f"{role} topic {topic!r} is not in the bag; it has: {source.describe()}"
            )
        if source.topics[topic] != msgtype:
            raise ReplayError(
                f"{role} topic {topic!r} has type {source.topics[topic]}, expected {msgtype}"
            )


def check_distinct(inputs: dict) -> None:
    """inputs: {role: topic}; ReplayError when two roles name one topic (its messages would be
    read as two kinds of image), before the bag is opened."""
    topics = list(inputs.values())
    twice = [f"--{role}-topic" for role, topic in inputs.items() if topics.count(topic) > 1]
    if twice:
        raise ReplayError(f"{', '.join(twice)} name the same topic: depth, NOCS and mask are "
                          "three images, each on its own topic")


def check_not_empty(source: BagSource, inputs: dict) -> None:
    """inputs: {role: topic}; ReplayError naming the first input topic without a message: no
    frame could be estimated from it, offline or played."""
    for role, topic in inputs.items():
        if source.counts.get(topic, 0) == 0:
            raise ReplayError(f"{role} topic {topic!r} has no messages")


@dataclass
class ReplaySummary:
    """What a replay did: counts, errors against truth (percent), speed, outputs, damage,
    estimates the publish gate held back."""

    frames_read: int = 0
    frames_estimated: int = 0
    errors_pct: list = field(default_factory=list)
    seconds: float = 0.0
    warm_up_seconds: float = 0.0
    out_dir: str = ""
    damaged: str = ""
    dropped: dict = field(default_factory=dict)
    csv_rows: int = 0
    held_back: int = 0  # frames estimated whose focal the publish gate held back
    held_reason: str = ""  # the gate's word on the last of them
    metadata_problem: str = ""  # the bag's metadata.yaml unreadable, its .mcap files read

    @property
    def fps(self) -> float:
        return self.frames_read / self.seconds if self.seconds > 0 else 0.0

    def text(self) -> str:
        lines = [
            f"frames read       {self.frames_read}",
            f"frames answered   {self.frames_estimated} with a CameraInfo",
        ]
        if 0 < self.frames_estimated < self.frames_read and not self.dropped:
            lines[-1] += (f"; {self.frames_read - self.frames_estimated} without: the window "
                          "had too few frames yet, or its std_rel was above max_uncertainty or "
                          "its focal outside focal_min..focal_max")
        if self.errors_pct:
            e = np.abs(np.asarray(self.errors_pct))
            lines.append(
                f"focal error       median {np.median(e):.2f}%, "
                f"90th percentile {np.percentile(e, 90):.2f}%"
                f" (over {e.size} estimates with truth)"
            )
        warm = (f"; the kernels' preparation, {self.warm_up_seconds:.1f} s, left out"
                if self.warm_up_seconds >= 0.05 else "")
        lines.append(f"throughput        {self.fps:.1f} frames/s ({self.seconds:.1f} s{warm})")
        if self.dropped:
            lines.append(
                "dropped input     "
                + ", ".join(f"{k}: {v}" for k, v in sorted(self.dropped.items()))
            )
        if self.damaged:
            lines.append(
                f"bag damaged       {self.damaged}; outputs hold what was estimated before"
            )
        lines.append(
            f"outputs           {self.out_dir}/estimates.csv, {self.out_dir}/fcop_output/, "
            f"{self.out_dir}/report.png"
        )
        return "\n".join(lines)
