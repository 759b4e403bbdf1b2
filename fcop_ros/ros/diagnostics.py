"""The node's /diagnostics status, built from a snapshot of its counters and state.

Plain functions over plain data (no rclpy, no node), so each level and message can be tested
alone: :class:`DiagnosticsInput` is what the node reads under its lock, :class:`RateWindow`
turns successive readings into rates over the last few seconds, :func:`status_fields` decides
level, message and key-values, :func:`diagnostic_status` wraps them in the message.
"""

from __future__ import annotations

import re
from collections import deque
from dataclasses import dataclass, field

import numpy as np
from diagnostic_msgs.msg import DiagnosticStatus, KeyValue

from .gate import held_back
from .intake import SILENT_SECONDS

OK, WARN, ERROR = DiagnosticStatus.OK, DiagnosticStatus.WARN, DiagnosticStatus.ERROR


@dataclass(frozen=True)
class DiagnosticsInput:
    """One reading of the node. ``window_estimate``: the window's current WindowEstimate;
    ``publishable``: whether its focal is within max_uncertainty (CameraInfo goes out);
    ``busy_for`` / ``age``: seconds the estimator has been busy with one frame / since it
    finished the last (None: idle / never); ``processing_ms``: recent per-frame estimation
    times; ``kernels``: what runs the estimator's kernels (numba or the numpy fallback);
    ``warming_up``: the estimator thread is still compiling or loading them; ``focal_range``:
    (focal_min, focal_max), which bounds every published focal."""

    now: float
    window_estimate: object
    publishable: bool
    window_fill: str
    max_uncertainty: float
    max_estimate_age: float
    matched: int
    processed: int
    skipped: int
    sync_dropped: int
    camera_info_published: int
    busy_for: float | None = None
    age: float | None = None
    processing_ms: tuple = ()
    dropped: dict = field(default_factory=dict)
    warnings: dict = field(default_factory=dict)
    kernels: str = ""
    warming_up: bool = False
    focal_range: tuple = (0.0, float("inf"))
    # Why the newest frame the estimator took gave no focal: its input refused ("dropped: ...")
    # or no evidence in it; "" if it gave one.
    last_reason: str = ""
    # Frames the estimator finished since the window was last emptied (start, reset).
    since_empty: int = 0
    # Why no CameraInfo can be built for the images the publishable focal belongs to (a
    # camera_info_in of another size, a principal point off the image); "" if it can.
    no_camera_info: str = ""
    # (input name, seconds since its last message, None before the first) for each image input.
    input_ages: tuple = ()
    # Seconds since the first message of any input (None before it): how long an input that
    # never sent has been silent.
    since_first_input: float | None = None
    # The queue_size the inputs' measured delays need, when the queue is too short ('' else).
    queue_advice: str = ""


@dataclass(frozen=True)
class Rates:
    """Frames matched, processed and skipped over the last ``span`` seconds, and their rates;
    ``answered``: depth images given a CameraInfo in that time; ``refused``: frames the
    estimator took that gave no focal in that time (input it refused, or no evidence);
    ``inputs``: messages of each image input in that time; ``drops``: the node's drops by
    reason in that time (None: not known, the totals since the start serve)."""

    span: float
    matched: int
    processed: int
    skipped: int
    answered: int = 0
    refused: int = 0
    inputs: tuple = ()
    drops: dict | None = None

    @property
    def frame_hz(self) -> float:
        return self.matched / self.span if self.span > 0 else 0.0

    @property
    def estimator_hz(self) -> float:
        return self.processed / self.span if self.span > 0 else 0.0


class RateWindow:
    """Rates over about the last ``seconds``: keeps the readings of successive diagnostics
    messages and compares the newest with the oldest one still within reach."""

    def __init__(self, seconds: float = 5.0, start: float | None = None):
        """``start``: when the counts were zero (the node's start): the first reading's rates
        are taken since then, where they would otherwise have no span."""
        self.seconds = seconds
        # (time, matched, processed, skipped, answered, refused, inputs, drops)
        self._samples: deque = deque()
        self._start = start

    def add(self, now: float, matched: int, processed: int, skipped: int,
            answered: int = 0, refused: int = 0, inputs: tuple = (),
            drops: dict | None = None) -> Rates:
        """``drops``: the node's drops by reason since the start (its dropped counter)."""
        inputs, drops = tuple(inputs), dict(drops or {})
        self._samples.append((now, matched, processed, skipped, answered, refused, inputs,
                              drops))
        while len(self._samples) > 1 and now - self._samples[1][0] >= self.seconds:
            self._samples.popleft()
        first = self._samples[0]
        if len(self._samples) == 1 and self._start is not None and self._start < now:
            first = (self._start, 0, 0, 0, 0, 0, (0,) * len(inputs), {})
        t0, m0, p0, s0, a0, r0, i0, d0 = first
        return Rates(now - t0, matched - m0, processed - p0, skipped - s0, answered - a0,
                     refused - r0, tuple(a - b for a, b in zip(inputs, i0)),
                     {k: v - d0.get(k, 0) for k, v in drops.items() if v > d0.get(k, 0)})


def status_fields(d: DiagnosticsInput, rates: Rates) -> tuple[bytes, str, dict]:
    """(level, message, {key: value}) of the node's status: ERROR when the estimator is stalled,
    WARN without a focal (saying so while the kernels are being prepared), when every input has
    been silent for SILENT_SECONDS (the camera stopped), when fewer than half of the slowest
    input's recent messages made a frame, with one held back by
    focal_range (changed at run time) or max_uncertainty, or for which no CameraInfo can be
    built (camera_info_in of another size than the images), when depth images keep coming but no
    complete frame has matched lately (the estimate ages), or when the estimator skipped more
    frames than it estimated lately, or when most frames estimated lately, five or more, gave
    no focal (the
    focal then comes from earlier frames, which a bad input can leave for a window's length);
    else OK."""
    win = d.window_estimate
    std = getattr(win, "std_rel", None)
    silent = _silent(d)
    lost = _slowest_lost(d, rates)
    if d.busy_for is not None and d.busy_for > d.max_estimate_age:
        level = ERROR
        message = (
            f"estimator stalled: busy with one frame for {d.busy_for:.1f} s (max_estimate_age "
            f"{d.max_estimate_age} s); CameraInfo carries an estimate {d.age or 0:.1f} s old"
        )
    elif win.focal is None and d.warming_up:
        level = WARN
        message = ("no focal estimate yet: the estimator is preparing its kernels (the first run "
                   "on a machine compiles them, up to a minute)")
    elif win.focal is None:
        why = win.reason
        if win.frames == 0 and d.since_empty:
            # Refused or failed frames never reach the window, which still says it has none.
            why = f"none of the {d.since_empty} frames estimated reached the window"
        level, message = WARN, f"no focal estimate yet: {why}"
        if d.last_reason:
            message += f"; the newest frame: {d.last_reason}"
        if silent and len(silent) == len(d.input_ages):
            message += f"; {_no_input(silent)}"
        elif d.matched == 0 and d.sync_dropped > 0:
            message += f"; no depth, NOCS and mask set has matched: {_sync_hint(d, silent, rates)}"
        elif silent:
            message += f"; {_sync_hint(d, silent, rates)}"
    elif silent and len(silent) == len(d.input_ages):
        level = WARN
        message = (f"focal {win.focal:.1f} px from an estimate {d.age or 0:.1f} s old: "
                   f"{_no_input(silent)}")
    elif not d.publishable:
        level = WARN
        message = (held_back(win, d.max_uncertainty, d.focal_range)
                   or f"focal {win.focal:.1f} px held back: no image size yet")
    elif d.no_camera_info:
        level = WARN
        message = f"focal {win.focal:.1f} px held back: no CameraInfo: {d.no_camera_info}"
    elif rates.answered > 0 and rates.matched == 0:
        level = WARN
        message = (
            f"focal {win.focal:.1f} px from an ageing estimate: {rates.answered} depth images "
            f"in the last {rates.span:.1f} s but no matched depth, NOCS and mask set "
            f"({_sync_hint(d, silent, rates)})"
        )
    elif lost:
        level = WARN
        name, sent = lost
        message = (
            f"focal {win.focal:.1f} px from few frames: only {rates.matched} of the {sent} "
            f"{name} messages in the last {rates.span:.1f} s made a frame "
            f"({_sync_hint(d, silent, rates)})"
        )
    elif rates.refused >= 5 and 2 * rates.refused > rates.processed:
        level = WARN
        message = (
            f"focal {win.focal:.1f} px from earlier frames: {rates.refused} of the "
            f"{rates.processed} frames estimated in the last {rates.span:.1f} s gave no focal"
            + (f" (the newest: {d.last_reason})" if d.last_reason else "")
        )
    elif rates.skipped > rates.processed:
        level = WARN
        message = (
            f"focal {win.focal:.1f} px; estimator behind: skipped {rates.skipped} of "
            f"{rates.matched} frames in the last {rates.span:.1f} s"
        )
    else:
        level, message = OK, f"focal {win.focal:.1f} px"
    values = {
        "focal_px": "" if win.focal is None else f"{win.focal:.3f}",
        "std_rel": "" if std is None else f"{std:.5f}",
        "max_uncertainty": str(d.max_uncertainty),
        "support_votes": str(win.support),
        "window_fill": d.window_fill,
        "frame_rate_hz": f"{rates.frame_hz:.2f}",
        "estimator_rate_hz": f"{rates.estimator_hz:.2f}",
        "estimate_age_s": "" if d.age is None else f"{d.age:.2f}",
        "estimator_busy_s": "" if d.busy_for is None else f"{d.busy_for:.2f}",
        "frames_processed": str(d.processed),
        "frames_skipped": str(d.skipped),
        "camera_info_published": str(d.camera_info_published),
        "sync_matched": str(d.matched),
        "sync_dropped": str(d.sync_dropped),
        # Blank before the first frame, as the other values nothing has measured yet.
        "processing_ms_median": f"{np.median(d.processing_ms):.2f}" if d.processing_ms else "",
        "processing_ms_max": f"{np.max(d.processing_ms):.2f}" if d.processing_ms else "",
        "estimator_kernels": d.kernels,
    }
    values.update({f"{name}_age_s": "" if age is None else f"{age:.2f}"
                   for name, age in d.input_ages})
    values.update({f"dropped_{k}": str(v) for k, v in sorted(d.dropped.items())})
    values.update({f"warning_{k}": str(v) for k, v in sorted(d.warnings.items())})
    return level, message, values


def _silent(d: DiagnosticsInput) -> list:
    """(name, seconds) of the inputs silent for SILENT_SECONDS or more (one that never sent is
    silent since the first message of another)."""
    heard = [age for _, age in d.input_ages if age is not None]
    if not heard:
        return []
    since_first = max(heard) if d.since_first_input is None else d.since_first_input
    return [(name, since_first if age is None else age) for name, age in d.input_ages
            if (since_first if age is None else age) >= SILENT_SECONDS]


def _no_input(silent: list) -> str:
    """What every input being silent means (``silent``: :func:`_silent`'s, all inputs)."""
    return (f"no input for {min(a for _, a in silent):.1f} s (camera stopped, or topics "
            "remapped?)")


def _slowest_lost(d: DiagnosticsInput, rates: Rates):
    """(name, messages) of the input that sent fewest messages lately, when five or more of them
    and fewer than half made a frame (each should: it is the one the others wait for), else
    None."""
    if not rates.inputs or len(rates.inputs) != len(d.input_ages):
        return None
    k = min(range(len(rates.inputs)), key=rates.inputs.__getitem__)
    sent = rates.inputs[k]
    if sent >= 5 and 2 * rates.matched < sent:
        return d.input_ages[k][0], sent
    return None


def _sync_hint(d: DiagnosticsInput, silent: list, rates: Rates) -> str:
    """Why depth, NOCS and mask do not match, and the parameter that answers it: an input silent
    now (``silent``: :func:`_silent`'s), else what the synchroniser's most frequent recent drops
    (counted as dropped 'sync_<reason>' and 'outlier_stamp_<input>') say."""
    if silent and len(silent) < len(d.input_ages):
        return " and ".join(f"no {name} message for {age:.1f} s" for name, age in silent) + (
            " (silent, or " + ("its topic" if len(silent) == 1 else "their topics")
            + " remapped elsewhere?)")
    recent = d.dropped if rates.drops is None else rates.drops
    unmatched = recent.get("sync_unmatched", 0)
    full = recent.get("sync_queue_full", 0)
    others = (
        (recent.get("sync_duplicate", 0), "dropped as duplicates: a stamp its input had already "
         "sent (is the driver stamping its images? each message needs a stamp of its own)"),
        (recent.get("sync_late", 0), "dropped as late: older than the newest matched frame "
         "(does an input send its messages out of order?)"),
        (sum(v for k, v in recent.items() if k.startswith("outlier_stamp_")),
         "dropped as outlier stamps, far from their input's clock (see the log)"),
    )
    count, words = max(others, key=lambda cw: cw[0])
    if count > max(unmatched, full):
        return f"{count} messages {words}"
    if unmatched >= full and unmatched and rates.matched:
        # Stamps that match for some frames are not different clocks: the others' messages of
        # these stamps never came.
        return (f"{unmatched} messages dropped as unmatched while {rates.matched} frames "
                "matched: no message of their stamps came on the other inputs (lost in "
                "transport? large images between processes need "
                "config/fastdds_large_images.xml; or an input that answers only some frames)")
    if unmatched >= full and unmatched:
        return (f"{unmatched} messages dropped as unmatched: the inputs' stamps differ (exact "
                "sync needs equal stamps; sync_mode approximate matches within sync_slop)")
    if full:
        return (f"{full} messages dropped from full queues: an input is stamped further "
                "behind the others than queue_size messages (" + (
                    d.queue_advice or "raise queue_size to cover its delay times the others' "
                    "rate") + ")")
    return "is the NOCS or mask topic silent?"


def diagnostic_status(
    name: str, hardware_id: str, d: DiagnosticsInput, rates: Rates
) -> DiagnosticStatus:
    """The DiagnosticStatus message of :func:`status_fields`."""
    level, message, values = status_fields(d, rates)
    st = DiagnosticStatus(name=name, hardware_id=hardware_id, level=level, message=message)
    st.values = [KeyValue(key=k, value=v) for k, v in values.items()]
    return st


class HealthNews:
    """What of /diagnostics the console should hear, for whoever watches only it (the camera
    stopping said nothing there): each problem once when it begins (a new level or a new cause;
    its numbers may change), and that it is over once the status is OK again. The start's plain
    'no focal estimate yet' (no frames, kernels, too few frames) is no news; with a cause after
    it (no input, nothing matched) it is."""

    def __init__(self):
        self._said = None  # the problem last said: (level, wording without its numbers)

    def __call__(self, level: bytes, message: str) -> tuple | None:
        """(level, line) to log for this status, or None."""
        if level == OK:
            if self._said is None:
                return None
            self._said = None
            return OK, f"healthy again: {message}"
        if message.startswith("no focal estimate yet") and ";" not in message:
            return None
        cause = (level, re.sub(r"\d+(\.\d+)?", "#", message))
        if cause == self._said:
            return None
        self._said = cause
        return level, message
