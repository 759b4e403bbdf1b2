"""fcop_replay's offline driver: a bag's image topics through the real FcopNode in this process,
one message at a time, into estimates.csv, an output bag and report.png (fcop_replay --help)."""

from __future__ import annotations

import sys
import time
from pathlib import Path

from ..core.camera import true_focal
from ..ros.dds import isolated, use_large_image_profile
from ..ros.spin import shut_down, spin_until as spin
from .bagio import BagError, BagSource, BagWriter, error_text, not_a_bag_of, remove_bag
from .cli import raise_ctrl_c
from .estimates_csv import EstimatesCsv, not_an_estimates_csv
from .replay_base import (
    IMAGE_TYPE,
    INFO_TYPE,
    OutputError,
    ReplayError,
    ReplaySummary,
    check_distinct,
    check_not_empty,
    check_out_dir,
    check_topics,
    writing,
)
from .replay_params import node_parameters
from .report import not_a_report, write_report

NODE_NAMESPACE = "/fcop"


def _check_encoding(role: str, topic: str, msg) -> None:
    from msg_adapters import DEPTH_ENCODINGS, MASK_ENCODINGS, NOCS_ENCODINGS

    supported = {"depth": DEPTH_ENCODINGS, "nocs": NOCS_ENCODINGS, "mask": MASK_ENCODINGS}[role]
    if msg.encoding not in supported:
        raise ReplayError(
            f"{role} topic {topic!r}: unsupported encoding {msg.encoding!r}; "
            f"supported: {', '.join(supported)}"
        )


def _check_encodings(source: BagSource, inputs: dict, decode) -> float:
    """ReplayError when the first message of an input topic has an encoding the node cannot
    read: checked before --out is touched. ``decode(raw)`` gives the Image. The bag is read
    only until each topic with messages has shown one; damage ends the check (the replay then
    meets it and keeps what came before). Returns the first input message's log time (s; 0
    when none could be read)."""
    role_of = {topic: role for role, topic in inputs.items()}
    left = {t for t in role_of if source.counts.get(t, 0)}
    it = source.messages(sorted(left))
    first = None
    try:
        while left:
            try:
                topic, log_ns, raw = next(it)
            except StopIteration:
                break
            except (ReplayError, BagError):
                raise
            except Exception as exc:  # damage: the replay reports it
                raise_ctrl_c(exc)
                break
            first = log_ns * 1e-9 if first is None else first
            if topic in left:
                left.discard(topic)
                _check_encoding(role_of[topic], topic, decode(raw))
    finally:
        close = getattr(it, "close", None)
        if close is not None:
            close()
    return first or 0.0


def _node_args(inputs: dict) -> list[str]:
    args = ["--ros-args", "-r", f"__ns:={NODE_NAMESPACE}"]
    for role, topic in inputs.items():
        args += ["-r", f"{role}:={topic}"]
    return args


def _not_the_input(bag, out_dir) -> None:
    """ReplayError when the input bag lies in the output bag's place, which --out clears."""
    out_bag = (Path(out_dir) / "fcop_output").resolve()
    src = Path(bag).resolve()
    if src == out_bag or out_bag in src.parents:
        raise ReplayError(
            f"the bag {bag} is where the output bag goes ({out_bag}), which a replay clears: "
            "choose another --out"
        )


def _prepare_out(out_dir) -> Path:
    """Create --out (a directory) after checking that its fcop_output, estimates.csv and
    report.png, if any, are a previous replay's; OutputError if impossible or not."""
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise OutputError(f"--out {out} exists and is not a directory")
    judges = {
        "fcop_output": ("an output bag", lambda path: not_a_bag_of(path, NODE_NAMESPACE + "/")),
        "estimates.csv": ("an estimates.csv", not_an_estimates_csv),
        "report.png": ("a report", not_a_report),
    }
    for name, (what, judge) in judges.items():
        why = judge(out / name)
        if why:
            raise OutputError(f"{out / name} exists and is not {what} of fcop_replay ({why}): "
                              "move it away or choose another --out")
    with writing(f"--out {out}"):
        out.mkdir(parents=True, exist_ok=True)
    return out


def _clear_output_bag(out_bag: Path) -> None:
    """Remove the previous output bag (checked by _prepare_out); OutputError if impossible."""
    with writing(f"{out_bag} (removing the previous output bag)"):
        remove_bag(out_bag)


def _note_held_back(node, summary: ReplaySummary, seen: list) -> None:
    """Count the frames the node estimated since the last call whose focal the publish gate
    held back (max_uncertainty, focal_min..focal_max): a run that published nothing says so
    instead of blaming its topics. ``seen``: [frames processed at the last call]. Called
    once the node is idle, so its tracker is read between frames."""
    processed = node.counts.processed
    new, seen[0] = processed - seen[0], processed
    win = node.window_estimate
    if new <= 0 or win is None or getattr(win, "focal", None) is None:
        return
    why = node.tracker.held_back()  # the node's own gate, with the settings it holds
    if why:
        summary.held_back += new
        summary.held_reason = why


def replay(
    bag,
    depth_topic: str,
    nocs_topic: str,
    mask_topic: str,
    out_dir,
    *,
    truth_topic: str | None = None,
    params_file: str | None = None,
    overrides=(),
    out_storage: str = "mcap",
    progress: bool | None = None,
    timeout: float = 60.0,
    summary: ReplaySummary | None = None,
) -> ReplaySummary:
    """Offline replay (see the module docstring). Raises ReplayError/BagError for unusable input
    or parameters (before --out is touched), OutputError when an output cannot be written (its
    message says what was lost); a bag damaged part-way is reported in the summary and its
    outputs keep what came before. ``summary``: filled as the run goes (its ``out_dir`` set once
    --out is written), so a caller that sees Ctrl-C knows what was written."""
    summary = summary if summary is not None else ReplaySummary()
    params = node_parameters(params_file, overrides)
    check_out_dir(out_dir)
    inputs = {"depth": depth_topic, "nocs": nocs_topic, "mask": mask_topic}
    check_distinct(inputs)
    use_large_image_profile()
    import rclpy
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node
    from rclpy.parameter import Parameter
    from rclpy.qos import qos_profile_sensor_data
    from rclpy.serialization import deserialize_message
    from sensor_msgs.msg import CameraInfo, Image

    from msg_adapters import stamp_ns

    from ..ros.node import FcopNode
    from ..ros.topics import OUTPUTS, type_name

    source = BagSource(bag)
    summary.metadata_problem = source.metadata_problem
    wanted = {role: (t, IMAGE_TYPE) for role, t in inputs.items()}
    if truth_topic is not None:
        wanted["truth"] = (truth_topic, INFO_TYPE)
    try:
        check_topics(source, wanted)
        check_not_empty(source, inputs | ({"truth": truth_topic} if truth_topic else {}))
        total = source.counts[depth_topic]
        first_log_time = _check_encodings(source, inputs,
                                          lambda raw: deserialize_message(raw, Image))
        _not_the_input(bag, out_dir)
        # Only now is --out touched: the CSV first, so an unwritable one keeps the previous
        # output bag.
        out = _prepare_out(out_dir)
        out_bag = out / "fcop_output"
        table = EstimatesCsv(out / "estimates.csv", truth_topic is not None, summary)
        summary.out_dir = str(out)
        try:
            _clear_output_bag(out_bag)
        except BaseException:
            table.close(final=False)
            raise
    except BaseException:
        source.close()
        raise
    role_of = {v: k for k, v in inputs.items()}
    rows: list[dict] = []
    processed = [0]
    state = {
        "node": None,
        "feeder": None,
        "executor": None,
        "writer": None,
        "bar": None,
        "bag_failed": False,
        "said_warming": False,
    }

    # The node times its inputs' arrivals on the bag's log time (queue_size advice, ages): fed
    # one message at a time, how fast they come says nothing of the bag.
    bag_time = [first_log_time]
    ctx = Context()
    with isolated() as domain:  # an offline replay keeps off the shell's ROS graph
        rclpy.init(context=ctx, args=[], domain_id=domain)
    t0 = time.perf_counter()
    sent = 0

    def run():
        nonlocal sent
        executor = state["executor"] = SingleThreadedExecutor(context=ctx)
        try:
            node = state["node"] = FcopNode(
                context=ctx,
                cli_args=_node_args(inputs),
                arrival_clock=lambda: bag_time[0],
                parameter_overrides=[Parameter(k, value=v) for k, v in params.items()],
            )
        except Exception as exc:  # checked above already; the node's own refusal, as one line
            text = (str(exc).strip().splitlines() or [type(exc).__name__])[-1]
            raise ReplayError(f"fcop_node did not start: {text}") from None
        feeder = state["feeder"] = Node("fcop_replay", context=ctx)
        pubs = {
            t: feeder.create_publisher(Image, t, qos_profile_sensor_data) for t in inputs.values()
        }
        outputs = {k: pub.topic_name for k, pub in node.outputs.items()}
        types = {k: type_name(cls) for k, cls in OUTPUTS.items()}
        got: dict[str, list] = {k: [] for k in outputs}
        consumed = {k: 0 for k in outputs}
        subs = [
            feeder.create_subscription(OUTPUTS[k], t, got[k].append, 100, raw=True)
            for k, t in outputs.items()
        ]
        executor.add_node(node)
        executor.add_node(feeder)

        def spin_until(cond, limit=timeout):
            """Spin until ``cond()`` holds; after ``limit`` s a ReplayError with the counts. Time
            the node spends compiling its kernels (a first run on a machine) does not count."""
            while not spin(executor, cond, limit, step=0.01):
                if node.warming_up:
                    if not state["said_warming"]:
                        state["said_warming"] = True
                        print("fcop_replay: the node is compiling its estimator's kernels (the "
                              "first run on this machine); waiting for it", file=sys.stderr)
                    continue
                n = node.counts
                raise ReplayError(
                    "the node did not answer in time (is the machine overloaded?) "
                    f"[received {n.received}/{sent}, matched {n.matched}, "
                    f"processed {n.processed}, published {n.frames_published}, "
                    f"outputs {[len(v) for v in got.values()]}]"
                )

        if progress if progress is not None else sys.stderr.isatty():
            from tqdm import tqdm

            state["bar"] = tqdm(total=total, unit="frame", desc="fcop_replay", file=sys.stderr)
        spin_until(
            lambda: (
                all(p.get_subscription_count() for p in pubs.values())
                and all(s.get_publisher_count() for s in subs)
            ),
            30,
        )
        with writing(out_bag):
            state["writer"] = BagWriter(out_bag, out_storage)
            state["writer"].__enter__()
        writer = state["writer"]

        def drain():
            """Write what the node published for the frames handed over so far."""

            def caught_up():
                # A frame the estimator skipped for a newer one is answered by that one.
                n = node.counts
                return n.processed + n.skipped >= n.matched and node.idle()

            spin_until(caught_up)
            publish = {
                "camera_info": True,
                "object_poses": node.get_parameter("publish_poses").value,
                "object_markers": node.get_parameter("publish_markers").value,
            }
            wanted = [k for k, on in publish.items() if on]

            def delivered():
                # CameraInfo goes out per depth image (one without its frame too: a truncated
                # bag's last), poses and markers per estimated frame.
                n = node.counts
                sent_out = {"camera_info": n.camera_info_published}
                return all(consumed[k] + len(got[k]) >= sent_out.get(k, n.frames_published)
                           for k in wanted)

            spin_until(delivered)
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
                        with writing(out_bag):
                            writer.write_raw(outputs[key], types[key], bytes(raw), stamp)
                    except OutputError:
                        state["bag_failed"] = True
                        raise
                got[key].clear()

        try:
            for topic, log_ns, raw in source.messages(
                list(inputs.values()) + [truth_topic] * bool(truth_topic)
            ):
                bag_time[0] = log_ns * 1e-9
                if topic == truth_topic:
                    info = deserialize_message(raw, CameraInfo)
                    table.truth(stamp_ns(info), true_focal(info.k[0], info.k[4]))
                    continue
                role = role_of[topic]
                pubs[topic].publish(raw)
                sent += 1
                spin_until(lambda: node.counts.received >= sent)
                if role == "depth":
                    summary.frames_read += 1
                    if state["bar"] is not None:
                        state["bar"].update(1)
                drain()
                _note_held_back(node, summary, processed)
        except (ReplayError, BagError):
            raise
        except Exception as exc:  # a damaged or truncated bag: keep what came before
            raise_ctrl_c(exc)
            source.damaged = f"unreadable after {sent} image messages ({error_text(exc)})"
        drain()
        _note_held_back(node, summary, processed)
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
        if state["node"] is not None:
            summary.warm_up_seconds = state["node"].warm_up_seconds
            summary.seconds -= summary.warm_up_seconds
        if state["bar"] is not None:
            step(state["bar"].close)
        if state["node"] is not None:
            summary.dropped = state["node"].counts.dropped
            step(state["node"].destroy_node)
        if state["feeder"] is not None:
            step(state["feeder"].destroy_node)
        if state["executor"] is not None:
            step(lambda: state["executor"].shutdown(timeout_sec=1.0))
        step(lambda: shut_down(ctx))
        step(source.close)
        if state["writer"] is not None:

            def close_bag():
                try:
                    with writing(out_bag):
                        state["writer"].__exit__(None, None, None)
                except OutputError:
                    state["bag_failed"] = True
                    raise

            step(close_bag)
        step(lambda: table.close(final=True))

        def report():
            with writing(out / "report.png"):
                write_report(out / "report.png", rows, summary)

        step(report)
        return problems

    def lost(problems) -> str:
        parts = [
            f"stopped after {summary.frames_read} of {total} frames",
            f"estimates.csv holds {table.written} of {summary.frames_estimated} estimates",
        ]
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
    return {
        "stamp_ns": stamp,
        "focal": float(info.k[0]),
        "cx": float(info.k[2]),
        "cy": float(info.k[5]),
        "support": int(support),
        "std_rel": float(std_rel) if std_rel is not None else None,
        "objects": objects,
    }
