"""fcop_replay: run a recorded bag through fcop_node, or play it for a live node.

Offline mode (default) streams the bag's three image topics through the real FcopNode in this
process (same class, synchroniser, window and parameters, spun by an executor; the messages go
through DDS), one message at a time so nothing is lost, as fast as the node runs, and writes
to --out: estimates.csv (row by row, flushed as it goes), an output bag of camera_info /
object_poses / object_markers, and report.png. Play mode (--play) publishes the bag's image
messages on their topics with the recorded timing, as `ros2 bag play --clock` would, and the
recorded time on /clock for nodes with use_sim_time.

Parameters: --params-file sections keyed '/**', '/**/fcop_node', 'fcop_node' or
'<namespace>/fcop_node' all apply (wildcard sections first, the node's own after them), then
every -p NAME:=VALUE; unknown names and invalid values are refused before anything runs.
"""
from __future__ import annotations

import argparse
import csv
import difflib
import os
import sqlite3
import sys
import threading
import time
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import yaml

from .bagio import BagError, BagSource, BagWriter
from .cli import HelpFormatter
from ..ros.config import config_path
from ..ros.dds import use_large_image_profile

IMAGE_TYPE = "sensor_msgs/msg/Image"
INFO_TYPE = "sensor_msgs/msg/CameraInfo"
CSV_COLUMNS = ["stamp_ns", "focal", "cx", "cy", "support", "std_rel", "objects"]
NODE_NAME = "fcop_node"
NODE_NAMESPACE = "/fcop"

EXIT_OK, EXIT_NOTHING, EXIT_INPUT, EXIT_DAMAGED, EXIT_OUTPUT, EXIT_INTERRUPTED = 0, 1, 2, 3, 4, 130
EXIT_CODES = {
    EXIT_OK: "done",
    EXIT_NOTHING: "nothing was estimated (the topics never matched or gave no evidence)",
    EXIT_INPUT: "unusable input or arguments: missing bag, unknown topic, wrong type, unsupported encoding, "
                "unknown parameter name, invalid parameter value or --params-file",
    EXIT_DAMAGED: "the bag is damaged: read (replayed or played) up to the damage; outputs keep what came before",
    EXIT_OUTPUT: "the outputs cannot be written (--out not a directory, read-only, disk full); the message says "
                 "what was lost",
    EXIT_INTERRUPTED: "interrupted (Ctrl-C)",
}


def exit_codes_text() -> str:
    return "exit codes:\n" + "\n".join(f"  {code:<4}{text}" for code, text in EXIT_CODES.items())


class ReplayError(RuntimeError):
    """A replay that cannot run as asked (bad bag, topic, type, encoding or parameter): exit 2."""


class OutputError(ReplayError):
    """An output that cannot be written (read-only, not a directory, disk full): exit 4."""


@contextmanager
def _writing(what):
    """Turn a failed write of an output into OutputError naming the output and the reason."""
    try:
        yield
    except (OSError, sqlite3.Error) as exc:
        reason = getattr(exc, "strerror", None) or str(exc) or type(exc).__name__
        raise OutputError(f"cannot write {what}: {reason}") from exc


@dataclass
class ReplaySummary:
    """What a replay did: counts, errors against truth (percent), speed, outputs, damage."""

    frames_read: int = 0
    frames_estimated: int = 0
    errors_pct: list = field(default_factory=list)
    seconds: float = 0.0
    out_dir: str = ""
    damaged: str = ""
    rejected: dict = field(default_factory=dict)
    csv_rows: int = 0

    @property
    def fps(self) -> float:
        return self.frames_read / self.seconds if self.seconds > 0 else 0.0

    def text(self) -> str:
        lines = [f"frames read       {self.frames_read}",
                 f"frames estimated  {self.frames_estimated}"]
        if self.errors_pct:
            e = np.abs(np.asarray(self.errors_pct))
            lines.append(f"focal error       median {np.median(e):.2f}%, 90th percentile {np.percentile(e, 90):.2f}%"
                         f" (over {e.size} estimates with truth)")
        lines.append(f"throughput        {self.fps:.1f} frames/s ({self.seconds:.1f} s)")
        if self.rejected:
            lines.append("rejected inputs   " + ", ".join(f"{k}: {v}" for k, v in sorted(self.rejected.items())))
        if self.damaged:
            lines.append(f"bag damaged       {self.damaged}; outputs hold what was estimated before")
        lines.append(f"outputs           {self.out_dir}/estimates.csv, {self.out_dir}/fcop_output/, "
                     f"{self.out_dir}/report.png")
        return "\n".join(lines)


# ----- node parameters: params file sections for any namespace, -p overrides, checked up front
_ROS_PARAMETERS = ("use_sim_time", "start_type_description_service")


def _sections(doc, prefix=""):
    """(key, ros__parameters) of every node section of a parameter file, nested namespaces joined."""
    for key, body in doc.items():
        if not isinstance(body, dict):
            raise ReplayError(f"section {prefix + str(key)!r} is not a mapping")
        full = f"{prefix}{key}"
        if "ros__parameters" in body:
            if not isinstance(body["ros__parameters"], dict):
                raise ReplayError(f"section {full!r}: ros__parameters is not a mapping")
            yield full, body["ros__parameters"]
        else:
            yield from _sections(body, full.rstrip("/") + "/")


def _applies(key: str, node_name: str) -> bool:
    """Does a parameter-file section apply to the replayed node? Its last name must be the node's
    or a wildcard: the namespace part is ignored, because the replayed node stands in for the
    user's node wherever that runs ('/**', '/**/fcop_node', 'fcop_node', '/camera/fcop_node')."""
    last = key.strip("/").split("/")[-1] if key.strip("/") else ""
    return last in (node_name, "*", "**")


def _flatten(params: dict, prefix="") -> dict:
    out = {}
    for k, v in params.items():
        if isinstance(v, dict):
            out.update(_flatten(v, f"{prefix}{k}."))
        else:
            out[f"{prefix}{k}"] = v
    return out


def load_params_file(path, node_name: str = NODE_NAME) -> dict:
    """{name: value} of every section of a ROS 2 parameter file that applies to ``node_name``
    (see :func:`_applies`); wildcard sections first so the node's own values win."""
    try:
        text = Path(path).read_text()
    except OSError as exc:
        raise ReplayError(f"cannot read --params-file {path}: {exc.strerror or exc}") from None
    try:
        doc = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        where = getattr(exc, "problem_mark", None)
        at = f" (line {where.line + 1})" if where is not None else ""
        raise ReplayError(f"--params-file {path} is not valid YAML{at}: {getattr(exc, 'problem', exc)}") from None
    if not isinstance(doc, dict):
        raise ReplayError(f"--params-file {path} is not a ROS 2 parameter file "
                          f"(expected '/**:' or '{node_name}:' with 'ros__parameters:' under it)")
    try:
        sections = [(k, v) for k, v in _sections(doc) if _applies(k, node_name)]
    except ReplayError as exc:
        raise ReplayError(f"--params-file {path}: {exc}") from None
    if not sections:
        raise ReplayError(f"--params-file {path} has no section for {node_name} (it has: "
                          f"{', '.join(str(k) for k in doc) or 'nothing'}); key it '/**:' or '{node_name}:'")
    sections.sort(key=lambda kv: 0 if "*" in kv[0] else 1)
    values = {}
    for _, params in sections:
        values.update(_flatten(params))
    return values


_TRUE = {"true", "True", "TRUE", "yes", "Yes", "YES", "on", "On", "ON"}
_FALSE = {"false", "False", "FALSE", "no", "No", "NO", "off", "Off", "OFF"}


def parse_value(text: str):
    """A -p value typed as rcl types it: bool words, integer, double (1e3 too), [lists], else string."""
    if text in _TRUE:
        return True
    if text in _FALSE:
        return False
    for kind in (int, float):
        try:
            return kind(text)
        except ValueError:
            pass
    if text.startswith("["):
        try:
            return yaml.safe_load(text)
        except yaml.YAMLError:
            pass
    if len(text) >= 2 and text[0] == text[-1] and text[0] in "'\"":
        return text[1:-1]
    return text


def parse_overrides(overrides) -> dict:
    values = {}
    for item in overrides or ():
        name, sep, text = item.partition(":=")
        if not sep or not name:
            raise ReplayError(f"-p expects NAME:=VALUE, got {item!r}")
        if text == "":
            raise ReplayError(f"-p {name}:= has no value")
        values[name] = parse_value(text)
    return values


def check_parameters(values: dict, where: dict) -> dict:
    """Check names, types, ranges and choices against fcop_node's declared parameters; return the
    values with integers given for double parameters made doubles. ``where`` names the source."""
    from ..ros.params import PARAMETERS, check_combination, defaults

    known = sorted(PARAMETERS)
    out = {}
    for name, value in values.items():
        src = where.get(name, "")
        if name in _ROS_PARAMETERS or name.startswith("qos_overrides."):
            out[name] = value
            continue
        if name not in PARAMETERS:
            close = difflib.get_close_matches(name, known, n=1)
            hint = f" (did you mean {close[0]}?)" if close else ""
            raise ReplayError(f"unknown parameter {name!r} from {src}{hint}; fcop_node's parameters: "
                              f"{', '.join(known)}")
        spec = PARAMETERS[name]
        default = spec.default
        if isinstance(default, float) and isinstance(value, int) and not isinstance(value, bool):
            value = float(value)
        if type(value) is not type(default):
            raise ReplayError(f"parameter {name} from {src} must be {type(default).__name__}, got {value!r}")
        lo, hi = spec.range or (None, None)
        if spec.range is not None and not isinstance(value, bool) and not lo <= value <= hi:
            raise ReplayError(f"parameter {name}={value} from {src} is outside [{lo}, {hi}]")
        if spec.choices and value not in spec.choices:
            raise ReplayError(f"parameter {name}={value!r} from {src} must be one of: {', '.join(spec.choices)}")
        out[name] = value

    full = defaults()
    full.update({k: v for k, v in out.items() if k in PARAMETERS})
    problem = check_combination(full)
    if problem:
        raise ReplayError(f"invalid parameters: {problem}")
    return out


def node_parameters(params_file: str | None, overrides=()) -> dict:
    """The checked parameters the replayed node gets: the params file (default: the package's
    config/fcop.yaml), then the -p overrides."""
    path = params_file if params_file is not None else config_path()
    values = load_params_file(path)
    where = {k: f"--params-file {path}" for k in values}
    cli = parse_overrides(overrides)
    values.update(cli)
    where.update({k: "-p" for k in cli})
    return check_parameters(values, where)


def _check_topics(source: BagSource, wanted: dict) -> None:
    """wanted: {role: (topic, expected type)}; raise ReplayError naming what the bag has instead."""
    for role, (topic, msgtype) in wanted.items():
        if topic not in source.topics:
            raise ReplayError(f"{role} topic {topic!r} is not in the bag; it has: {source.describe()}")
        if source.topics[topic] != msgtype:
            raise ReplayError(f"{role} topic {topic!r} has type {source.topics[topic]}, expected {msgtype}")


def _check_encoding(role: str, msg) -> None:
    from msg_adapters import DEPTH_ENCODINGS, MASK_ENCODINGS, NOCS_ENCODINGS
    supported = {"depth": DEPTH_ENCODINGS, "nocs": NOCS_ENCODINGS, "mask": MASK_ENCODINGS}[role]
    if msg.encoding not in supported:
        raise ReplayError(f"{role} topic: unsupported encoding {msg.encoding!r}; supported: {', '.join(supported)}")


def _node_args(inputs: dict) -> list[str]:
    args = ["--ros-args", "-r", f"__ns:={NODE_NAMESPACE}"]
    for role, topic in inputs.items():
        args += ["-r", f"{role}:={topic}"]
    return args


def _prepare_out(out_dir) -> Path:
    """Create --out (a directory) and clear a previous output bag; OutputError if impossible."""
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise OutputError(f"--out {out} exists and is not a directory")
    with _writing(f"--out {out}"):
        out.mkdir(parents=True, exist_ok=True)
    out_bag = out / "fcop_output"
    if out_bag.is_dir() and not out_bag.is_symlink():
        import shutil
        with _writing(f"{out_bag} (removing the previous output bag)"):
            shutil.rmtree(out_bag)
    elif out_bag.exists() or out_bag.is_symlink():
        with _writing(f"{out_bag} (removing the previous output bag)"):
            out_bag.unlink()
    return out


class _EstimatesCsv:
    """estimates.csv, one row per published estimate, written and flushed as it comes, so a
    failure later loses only what follows. With a truth topic a row waits for the truth of its
    stamp (a truth message may follow its frame's images in the bag): it is written once a
    truth message at or after its stamp has been read, or at the end."""

    def __init__(self, path: Path, with_truth: bool, summary: ReplaySummary):
        self.path, self.with_truth, self.summary = path, with_truth, summary
        self.cols = CSV_COLUMNS + (["focal_true", "focal_error_pct"] if with_truth else [])
        self.pending: list[dict] = []
        self.truth_stamps: list[int] = []
        self.truth_values: list[float] = []
        self.written = 0
        self.fh = None
        with _writing(path):
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
        if i < 0:
            return
        row["focal_true"] = float(self.truth_values[i])
        row["focal_error_pct"] = 100.0 * (row["focal"] / row["focal_true"] - 1.0)
        self.summary.errors_pct.append(abs(row["focal_error_pct"]))

    def _release(self, final: bool = False) -> None:
        while self.pending:
            row = self.pending[0]
            if self.with_truth and not final and not (self.truth_stamps and self.truth_stamps[-1] >= row["stamp_ns"]):
                return
            self.pending.pop(0)
            self._attach(row)
            with _writing(self.path):
                self._line([("" if row.get(c) is None else
                             f"{row[c]:.6g}" if c == "std_rel" and isinstance(row.get(c), float) else
                             f"{row[c]:.4f}" if isinstance(row.get(c), float) else row.get(c, "")) for c in self.cols])
            self.written += 1
            self.summary.csv_rows = self.written

    def close(self, final: bool = True) -> None:
        try:
            if final:
                self._release(final=True)
        finally:
            if self.fh is not None:
                fh, self.fh = self.fh, None
                with _writing(self.path):
                    fh.close()


def replay(bag, depth_topic: str, nocs_topic: str, mask_topic: str, out_dir, *, truth_topic: str | None = None,
           params_file: str | None = None, overrides=(), out_storage: str = "mcap", progress: bool | None = None,
           timeout: float = 60.0) -> ReplaySummary:
    """Offline replay (see the module docstring). Raises ReplayError/BagError for unusable input
    or parameters (before anything runs), OutputError when an output cannot be written (its
    message says what was lost); a bag damaged part-way is reported in the summary and its
    outputs keep what came before."""
    params = node_parameters(params_file, overrides)
    use_large_image_profile()
    import rclpy
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node
    from rclpy.parameter import Parameter
    from geometry_msgs.msg import PoseArray
    from rclpy.qos import qos_profile_sensor_data
    from rclpy.serialization import deserialize_message
    from sensor_msgs.msg import CameraInfo, Image
    from visualization_msgs.msg import MarkerArray

    from msg_adapters import stamp_ns

    from ..ros.node import FcopNode

    inputs = {"depth": depth_topic, "nocs": nocs_topic, "mask": mask_topic}
    source = BagSource(bag)
    wanted = {role: (t, IMAGE_TYPE) for role, t in inputs.items()}
    if truth_topic is not None:
        wanted["truth"] = (truth_topic, INFO_TYPE)
    summary = ReplaySummary()
    try:
        _check_topics(source, wanted)
        total = source.counts.get(depth_topic, 0)
        if total == 0:
            raise ReplayError(f"depth topic {depth_topic!r} has no messages")
        out = _prepare_out(out_dir)
        summary.out_dir = str(out)
        table = _EstimatesCsv(out / "estimates.csv", truth_topic is not None, summary)
    except BaseException:
        source.close()
        raise
    out_bag = out / "fcop_output"
    role_of = {v: k for k, v in inputs.items()}
    rows: list[dict] = []
    checked = set()
    state = {"node": None, "feeder": None, "executor": None, "writer": None, "bar": None, "bag_failed": False}

    ctx = Context()
    rclpy.init(context=ctx, args=[])
    t0 = time.perf_counter()
    sent = 0

    def run():
        nonlocal sent
        executor = state["executor"] = SingleThreadedExecutor(context=ctx)
        try:
            node = state["node"] = FcopNode(context=ctx, cli_args=_node_args(inputs),
                                            parameter_overrides=[Parameter(k, value=v) for k, v in params.items()])
        except Exception as exc:  # checked above already; the node's own refusal, as one line
            text = (str(exc).strip().splitlines() or [type(exc).__name__])[-1]
            raise ReplayError(f"fcop_node did not start: {text}") from None
        feeder = state["feeder"] = Node("fcop_replay", context=ctx)
        pubs = {t: feeder.create_publisher(Image, t, qos_profile_sensor_data) for t in inputs.values()}
        outputs = {"camera_info": node.pub_info.topic_name, "object_poses": node.pub_poses.topic_name,
                   "object_markers": node.pub_markers.topic_name}
        types = {"camera_info": INFO_TYPE, "object_poses": "geometry_msgs/msg/PoseArray",
                 "object_markers": "visualization_msgs/msg/MarkerArray"}
        got: dict[str, list] = {k: [] for k in outputs}
        consumed = {k: 0 for k in outputs}
        classes = {"camera_info": CameraInfo, "object_poses": PoseArray, "object_markers": MarkerArray}
        subs = [feeder.create_subscription(classes[k], t, got[k].append, 100, raw=True) for k, t in outputs.items()]
        executor.add_node(node)
        executor.add_node(feeder)

        def spin_until(cond, limit=timeout):
            deadline = time.monotonic() + limit
            while not cond():
                if time.monotonic() > deadline:
                    n = node.counts
                    raise ReplayError("the node did not answer in time (is the machine overloaded?) "
                                      f"[received {n.received}/{sent}, matched {n.matched}, "
                                      f"processed {n.processed}, published {n.published}, "
                                      f"outputs {[len(v) for v in got.values()]}]")
                executor.spin_once(timeout_sec=0.01)

        if progress if progress is not None else sys.stderr.isatty():
            from tqdm import tqdm
            state["bar"] = tqdm(total=total, unit="frame", desc="fcop_replay", file=sys.stderr)
        spin_until(lambda: all(p.get_subscription_count() for p in pubs.values())
                   and all(s.get_publisher_count() for s in subs), 30)
        with _writing(out_bag):
            state["writer"] = BagWriter(out_bag, out_storage)
            state["writer"].__enter__()
        writer = state["writer"]

        def drain():
            """Write what the node published for the frames handed over so far."""
            def caught_up():
                n = node.counts
                return n.processed >= n.matched and node.idle()

            spin_until(caught_up)
            publish = {"camera_info": True, "object_poses": node.get_parameter("publish_poses").value,
                       "object_markers": node.get_parameter("publish_markers").value}
            wanted = [k for k, on in publish.items() if on]
            spin_until(lambda: all(consumed[k] + len(got[k]) >= node.counts.published for k in wanted))
            for key in outputs:
                consumed[key] += len(got[key])
                for raw in got[key]:
                    if key == "camera_info":
                        info = deserialize_message(raw, CameraInfo)
                        stamp = stamp_ns(info)
                        row = _row(info, stamp, node)
                        rows.append(row)
                        summary.frames_estimated += 1
                        table.add(row)
                    else:
                        stamp = rows[-1]["stamp_ns"] if rows else 0
                    try:
                        with _writing(out_bag):
                            writer.write_raw(outputs[key], types[key], bytes(raw), stamp)
                    except OutputError:
                        state["bag_failed"] = True
                        raise
                got[key].clear()

        try:
            for topic, _, raw in source.messages(list(inputs.values()) + [truth_topic] * bool(truth_topic)):
                if topic == truth_topic:
                    info = deserialize_message(raw, CameraInfo)
                    table.truth(stamp_ns(info), float(info.k[0]))
                    continue
                role = role_of[topic]
                if role not in checked:
                    _check_encoding(role, deserialize_message(raw, Image))
                    checked.add(role)
                pubs[topic].publish(raw)
                sent += 1
                spin_until(lambda: node.counts.received >= sent)
                if role == "depth":
                    summary.frames_read += 1
                    if state["bar"] is not None:
                        state["bar"].update(1)
                drain()
        except (ReplayError, BagError):
            raise
        except Exception as exc:  # a damaged or truncated bag: keep what came before
            source.damaged = f"{type(exc).__name__}: {exc}"
        drain()
        summary.damaged = source.damaged

    def finish(ok: bool) -> list[OutputError]:
        """Close everything; never raises. Returns the outputs that could not be finished."""
        problems = []

        def step(fn):
            try:
                fn()
            except OutputError as exc:
                problems.append(exc)
            except Exception:  # noqa: BLE001 - cleanup must not hide the real error
                pass

        summary.seconds = time.perf_counter() - t0
        if state["bar"] is not None:
            step(state["bar"].close)
        if state["node"] is not None:
            summary.rejected = state["node"].counts.rejected
            step(state["node"].destroy_node)
        if state["feeder"] is not None:
            step(state["feeder"].destroy_node)
        if state["executor"] is not None:
            step(lambda: state["executor"].shutdown(timeout_sec=1.0))
        step(ctx.try_shutdown)
        step(source.close)
        if state["writer"] is not None:
            def close_bag():
                try:
                    with _writing(out_bag):
                        state["writer"].__exit__(None, None, None)
                except OutputError:
                    state["bag_failed"] = True
                    raise
            step(close_bag)
        step(lambda: table.close(final=True))

        def report():
            with _writing(out / "report.png"):
                write_report(out / "report.png", rows, summary)
        step(report)
        return problems

    def lost(problems) -> str:
        parts = [f"stopped after {summary.frames_read} of {total} frames",
                 f"estimates.csv holds {table.written} of {summary.frames_estimated} estimates"]
        if state["bag_failed"]:
            parts.append("the output bag is incomplete")
        if any("report.png" in str(p) for p in problems):
            parts.append("report.png not written")
        return "; ".join(parts)

    try:
        run()
    except OutputError as exc:
        problems = finish(False)
        raise OutputError(f"{exc}; {lost(problems)}") from None
    except BaseException:
        finish(False)
        raise
    problems = finish(True)
    if problems:
        raise OutputError(f"{problems[0]}; {lost(problems)}")
    return summary


def _row(info, stamp, node) -> dict:
    """One estimates.csv row from a published CameraInfo and the window estimate behind it: the
    node's latest publication when it is of this stamp, else the window's current estimate."""
    latest = node.latest
    if latest is not None and latest.stamp_ns == stamp:
        std_rel, support, objects = latest.std_rel, latest.support, len(latest.objects)
    else:
        win = node.window_estimate
        std_rel, support, objects = getattr(win, "std_rel", None), win.support, 0
    return {"stamp_ns": stamp, "focal": float(info.k[0]), "cx": float(info.k[2]), "cy": float(info.k[5]),
            "support": int(support), "std_rel": float(std_rel) if std_rel is not None else None,
            "objects": objects}


def write_report(path: Path, rows, summary: ReplaySummary) -> None:
    """report.png: the published focal estimate over time with its ±2σ band (σ = the window's
    relative standard error std_rel) and the truth; below, the signed error against the truth."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax, ax2) = plt.subplots(2, 1, figsize=(9, 6.5), sharex=True, gridspec_kw={"height_ratios": [3, 2]})
    has_truth = any("focal_true" in r for r in rows)
    if rows:
        t = (np.array([r["stamp_ns"] for r in rows]) - rows[0]["stamp_ns"]) * 1e-9
        f = np.array([r["focal"] for r in rows])
        sd = np.array([np.nan if r.get("std_rel") is None else r["std_rel"] for r in rows], dtype=float)
        med = f", median σ {100 * np.nanmedian(sd):.2g}%" if np.isfinite(sd).any() else ""
        ax.fill_between(t, f * (1 - 2 * sd), f * (1 + 2 * sd), color="tab:blue", alpha=0.25, step="post",
                        linewidth=0, label=f"±2σ (σ = window std_rel{med})")
        ax.plot(t, f, color="tab:blue", drawstyle="steps-post", label="published focal (window)")
        if has_truth:
            tt = np.array([ti for ti, r in zip(t, rows) if "focal_true" in r])
            ft = np.array([r["focal_true"] for r in rows if "focal_true" in r])
            ax.plot(tt, ft, "k--", drawstyle="steps-post", label="truth")
            err = np.array([r["focal_error_pct"] for r in rows if "focal_true" in r])
            band = 200.0 * np.array([sd[i] for i, r in enumerate(rows) if "focal_true" in r])
            ax2.fill_between(tt, -band, band, color="tab:blue", alpha=0.25, step="post", linewidth=0,
                             label="±2σ")
            ax2.plot(tt, err, color="tab:red", drawstyle="steps-post", label="estimate − truth")
            ax2.axhline(0.0, color="k", linewidth=0.8)
            # A robust scale, so a bias of a percent shows next to the spike of a zoom; clipped
            # points are counted in the panel.
            finite_band = band[np.isfinite(band)]
            lim = max(1.0, 1.5 * float(np.percentile(np.abs(err), 90)),
                      1.2 * float(finite_band.max()) if finite_band.size else 0.0)
            ax2.set_ylim(-lim, lim)
            clipped = int((np.abs(err) > lim).sum())
            if clipped:
                ax2.text(0.01, 0.04, f"{clipped} estimate(s) beyond ±{lim:.1f}% off scale (max "
                         f"{np.abs(err).max():.1f}%)", transform=ax2.transAxes, fontsize="small", color="tab:red")
            ax2.legend(loc="upper right", fontsize="small")
        else:
            ax2.text(0.5, 0.5, "no truth topic: no error to show", ha="center", va="center",
                     transform=ax2.transAxes, color="0.4")
    else:
        ax.text(0.5, 0.5, "no estimate was published", ha="center", va="center", transform=ax.transAxes)
    ax.set_ylabel("focal length [px]")
    title = f"fcop_replay: {summary.frames_estimated} of {summary.frames_read} frames estimated"
    if summary.errors_pct:
        title += f", median |error| {np.median(summary.errors_pct):.2f}%"
    ax.set_title(title)
    if rows:
        ax.legend(loc="best", fontsize="small")
    ax.grid(alpha=0.3)
    ax2.set_ylabel("signed error [%]")
    ax2.set_xlabel("time since first estimate [s]")
    ax2.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


@dataclass
class PlayResult:
    """What a --play run did: messages published, /clock messages, and the damage it met."""

    published: int = 0
    clock: int = 0
    damaged: str = ""


def _readable(source: BagSource, topics):
    """The bag's messages up to the first damage (then ``source.damaged`` says what it was)."""
    it = source.messages(topics)
    while True:
        try:
            item = next(it)
        except StopIteration:
            return
        except Exception as exc:  # a damaged storage read through rosbags: stop here, say why
            source.damaged = source.damaged or f"{type(exc).__name__}: {exc}"
            return
        yield item


def play(bag, image_topics, *, rate: float = 1.0, loop: bool = False, context=None, stop: threading.Event | None = None,
         qos_depth: int = 10, clock: bool = True, clock_hz: float = 40.0) -> PlayResult:
    """Publish the bag's messages of ``image_topics`` with the recorded timing scaled by ``rate``.

    With ``clock`` the bag's time goes out on /clock (rosgraph_msgs/Clock), as `ros2 bag play
    --clock` does: the recorded time of every message just before it, and in between at
    ``clock_hz`` (0: only at the messages), so nodes with use_sim_time follow the bag. ``context``
    is an initialised rclpy Context (default: the global one, initialised here); ``stop`` ends
    playback early. A damaged bag is played up to the damage (``PlayResult.damaged``)."""
    import rclpy
    from rclpy.node import Node
    from rosgraph_msgs.msg import Clock
    from sensor_msgs.msg import Image

    if not rate > 0:
        raise ReplayError("--rate must be > 0")
    if clock_hz < 0:
        raise ReplayError("--clock-hz must be >= 0")
    source = BagSource(bag)
    try:
        _check_topics(source, {f"image {i + 1}": (t, IMAGE_TYPE) for i, t in enumerate(image_topics)})
    except ReplayError:
        source.close()
        raise
    own = context is None
    if own:
        use_large_image_profile()
        rclpy.init()
    node = Node("fcop_player", context=context)
    pubs = {t: node.create_publisher(Image, t, qos_depth) for t in image_topics}
    clock_pub = node.create_publisher(Clock, "/clock", 10) if clock else None
    stop = stop or threading.Event()
    result = PlayResult()
    last_clock = [None]

    def tick(ns: int) -> None:
        if last_clock[0] is not None and ns <= last_clock[0]:
            return
        msg = Clock()
        msg.clock.sec, msg.clock.nanosec = divmod(int(ns), 1_000_000_000)
        clock_pub.publish(msg)
        last_clock[0] = ns
        result.clock += 1

    def wait_until(due: float, start_wall: float, start_bag: int, ts: int) -> bool:
        """Sleep until ``due`` (monotonic), ticking /clock meanwhile; False when stopped."""
        period = 1.0 / clock_hz if clock_pub is not None and clock_hz > 0 else None
        while True:
            left = due - time.monotonic()
            if left <= 0:
                return True
            if stop.wait(min(left, period) if period else left):
                return False
            if period and time.monotonic() < due:
                tick(min(ts, start_bag + int((time.monotonic() - start_wall) * rate * 1e9)))

    try:
        while not stop.is_set():
            start_wall, start_bag = None, None
            last_clock[0] = None  # a loop starts the bag's time over, as rosbag2 does
            for topic, ts, raw in _readable(source, image_topics):
                if stop.is_set():
                    break
                if start_wall is None:
                    start_wall, start_bag = time.monotonic(), ts
                if not wait_until(start_wall + (ts - start_bag) * 1e-9 / rate, start_wall, start_bag, ts):
                    break
                if clock_pub is not None:
                    tick(ts)
                pubs[topic].publish(raw)
                result.published += 1
            result.damaged = source.damaged
            if not loop or start_wall is None:
                break
    finally:
        node.destroy_node()
        source.close()
        if own and rclpy.ok():
            rclpy.shutdown()
    return result


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="fcop_replay", description=__doc__, epilog=exit_codes_text(),
                                 formatter_class=HelpFormatter)
    ap.add_argument("bag", help="ROS 2 bag directory (sqlite3 or mcap)")
    ap.add_argument("--depth-topic", required=True, help="sensor_msgs/Image topic of the metric depth (required)")
    ap.add_argument("--nocs-topic", required=True, help="sensor_msgs/Image topic of the NOCS map (required)")
    ap.add_argument("--mask-topic", required=True, help="sensor_msgs/Image topic of the instance mask (required)")
    ap.add_argument("--truth-topic", default=None,
                    help="sensor_msgs/CameraInfo topic with the true intrinsics: adds focal_true and "
                         "focal_error_pct to the CSV and the error panel to the report (default: none)")
    ap.add_argument("--out", default="fcop_replay_out", help="output directory (offline mode)")
    ap.add_argument("--params-file", default=None,
                    help="ROS 2 parameter file for the node; sections '/**', '/**/fcop_node', 'fcop_node' "
                         "and '<ns>/fcop_node' apply (default: the package's config/fcop.yaml)")
    ap.add_argument("-p", dest="overrides", action="append", default=[], metavar="NAME:=VALUE",
                    help="set one node parameter, after the params file (repeatable)")
    ap.add_argument("--out-storage", default="mcap", choices=["mcap", "sqlite3"], help="storage of the output bag")
    ap.add_argument("--play", action="store_true",
                    help="publish the image topics with the recorded timing (and /clock) instead of replaying")
    ap.add_argument("--rate", type=float, default=1.0, help="play mode: speed factor")
    ap.add_argument("--loop", action="store_true", help="play mode: start over at the end")
    ap.add_argument("--no-clock", dest="clock", action="store_false",
                    help="play mode: do not publish the recorded time on /clock")
    ap.add_argument("--clock-hz", type=float, default=40.0,
                    help="play mode: /clock messages per second of wall time between the bag's messages "
                         "(one also goes out with every message; 0 = only those)")
    return ap


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    try:
        if args.play:
            res = play(args.bag, [args.depth_topic, args.nocs_topic, args.mask_topic], rate=args.rate,
                       loop=args.loop, clock=args.clock, clock_hz=args.clock_hz)
            print(f"published {res.published} messages" + (f" and {res.clock} on /clock" if args.clock else ""))
            if res.damaged:
                print(f"fcop_replay: bag damaged ({res.damaged}); played the {res.published} messages before "
                      "the damage", file=sys.stderr)
                return EXIT_DAMAGED
            return EXIT_OK
        summary = replay(args.bag, args.depth_topic, args.nocs_topic, args.mask_topic, args.out,
                         truth_topic=args.truth_topic, params_file=args.params_file, overrides=args.overrides,
                         out_storage=args.out_storage)
    except OutputError as exc:
        print(f"fcop_replay: {exc}", file=sys.stderr)
        return EXIT_OUTPUT
    except (ReplayError, BagError) as exc:
        print(f"fcop_replay: {exc}", file=sys.stderr)
        return EXIT_INPUT
    except KeyboardInterrupt:
        return EXIT_INTERRUPTED
    print(summary.text())
    if summary.frames_read and not summary.frames_estimated:
        print("fcop_replay: no frame was estimated: the three topics never matched or gave no evidence "
              "(see 'rejected inputs')", file=sys.stderr)
        return EXIT_NOTHING
    return EXIT_DAMAGED if summary.damaged else EXIT_OK


if __name__ == "__main__":
    raise SystemExit(main())
