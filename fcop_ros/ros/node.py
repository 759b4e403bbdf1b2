"""fcop_node: live focal length from depth, NOCS and instance-mask images.

A thin shell around :mod:`fcop_ros.core`. Input side (subscription callbacks, cheap): every
message passes the stamp check and the synchroniser (:mod:`fcop_ros.ros.sync`); every depth image
that passes gets its CameraInfo at once, carrying the window's current estimate; every matched
frame replaces the one in a one-slot hand-off. Estimator side (a worker thread): it takes the
newest complete frame whenever it is free, estimates it, updates the sliding window (and with
it the estimate the next depth images carry) and publishes that frame's poses and markers. So
publishing never waits for the estimator, and the estimator never works on a backlog.
"""

from __future__ import annotations

import sys
import threading
import time
import traceback
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import rclpy
import rclpy.logging
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from rcl_interfaces.msg import SetParametersResult
from rclpy.exceptions import InvalidServiceNameException, ParameterException
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.clock import Clock, ClockType
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos_overriding_options import InvalidQosOverridesError, QoSOverridingOptions
from sensor_msgs.msg import CameraInfo, Image
from sensor_msgs.srv import SetCameraInfo
from std_srvs.srv import Trigger

from msg_adapters import (DEPTH_ENCODINGS, ImageFormatError, check_image, marker_array,
                          object_poses, pose_array, stamp_ns)

from ..core import compiled, estimate_poses
from .allocator import limit_allocator_arenas
from .calibration import calibration_path, save_calibration
from .camera_info_output import CameraInfoOutput, LatestEstimate
from .command_line import USAGE, params_file_problem, rcl_params_error, wants_help
from .diagnostics import DiagnosticsInput, HealthNews, RateWindow, diagnostic_status
from .frame_estimate import estimate_frame
from .frame_outcome import frame_outcome
from .intake import Intake
from .intrinsics import (IntrinsicsRefused, Refused, at_full_resolution, camera_info_with,
                         intrinsics, raw_camera)
from .ledger import NodeLedger
from . import node_parameters
from .params import (
    ESTIMATOR_PARAMETERS,
    GATE_PARAMETERS,
    PARAMETERS,
    SYNC_PARAMETERS,
    WINDOW_PARAMETERS,
    ParameterError,
    check_combination,
    check_words,
    estimator_options,
    gate_settings,
    not_allowed,
    sync_settings,
    window_options,
)
from .qos import input_qos, latched_qos, output_qos, refused_override
from .spin import shut_down
from .sync import StampSynchronizer
from .throttle import LogThrottle
from .topics import CAMERA_INFO_IN, INPUTS, OUTPUTS
from .tracker import FocalTracker
from .worker import LatestSlotWorker

RCLError = _rclpy.RCLError


@dataclass(frozen=True)
class NodeCounts:
    """The node's counters at one moment: input messages ``received``, frames ``matched`` by the
    synchroniser, ``processed`` by the estimator, ``frames_published`` (their window estimate was
    publishable: poses and markers), ``skipped`` in the hand-off for newer ones, CameraInfo
    messages, input and frames ``dropped`` and ``warnings`` (accepted input that deserved a word),
    by reason (see :class:`.ledger.NodeLedger`)."""

    received: int
    matched: int
    processed: int
    frames_published: int
    skipped: int
    camera_info_published: int
    dropped: Counter
    warnings: Counter


class FcopNode(Node):
    """The fcop_node ROS 2 node (see the package README for topics, parameters and the rules).

    ``arrival_clock``: seconds, the clock on which the inputs' arrivals are timed (their rates,
    ages and delays, queue_size advice among them) and the estimator's busy time: monotonic
    time, or in an offline replay the bag's log time of the message being fed, so that the
    advice describes the bag rather than how fast the replay ran."""

    def __init__(self, node_name: str = "fcop_node", *,
                 arrival_clock: Callable[[], float] = time.monotonic, **kwargs):
        self.worker = None  # destroy_node works even when the parameters are refused
        super().__init__(node_name, **kwargs)
        try:
            self.p = node_parameters.declare(self)
        except ParameterError:
            Node.destroy_node(self)
            raise
        if hasattr(self, "add_pre_set_parameters_callback"):  # rclpy of Jazzy and later
            self.add_pre_set_parameters_callback(self._before_set)
        self.add_on_set_parameters_callback(self._on_set_parameters)

        self._now = arrival_clock  # the clock of rates and ages; replaceable in tests
        self.ledger = NodeLedger()  # counters and reasons, under self._lock
        self.last_estimate = None  # the FocalEstimate of the newest processed frame
        # Frame and estimator rates over 5 s, for diagnostics (the first reading: since start).
        self._rates = RateWindow(5.0, start=self._now())
        self._throttle = LogThrottle(self.get_logger())
        self._lock = threading.Lock()
        # The one-slot hand-off to the estimator thread; its clear() on every reset discards the
        # frames taken before it. Started once the node is complete.
        self.worker = LatestSlotWorker(
            self._estimate_item,
            self._on_worker_error,
            now=lambda: self._now(),
            name="fcop_estimator",
            before=self._warm_up_kernels,
        )
        self._warming_up = True  # until the worker has its kernels (see _warm_up_kernels)
        self.warm_up_seconds = 0.0  # what preparing them took (replay's throughput leaves it out)
        self._cam_in: CameraInfo | None = None
        # The CameraInfo side: depth stamps answered, the latest publication, the newest poses.
        self.info_out = CameraInfoOutput(self._send_camera_info, self._camera_info)
        self._warned_distortion = False
        self._health_news = HealthNews()  # what of /diagnostics the log says
        self._traceback_said = False
        self._rng = np.random.default_rng(None if self.p["seed"] < 0 else int(self.p["seed"]))
        self.intake = Intake(self._new_sync(), INPUTS)
        self.estimator_options = estimator_options(self.p)
        # The window, the image size it holds and the publish gate; under self._lock.
        self.tracker = FocalTracker(
            window_options(self.p), *gate_settings(self.p))
        try:
            self._create_topics()
        except ParameterError:
            Node.destroy_node(self)  # the worker has not started
            raise
        self.srv_reset = self.create_service(Trigger, "~/reset", self._on_reset)
        self.srv_save = self.create_service(
            Trigger, "~/save_calibration", self._on_save_calibration
        )
        try:
            self.set_info_client = self._set_camera_info_client()
        except ParameterError:
            Node.destroy_node(self)  # the worker has not started
            raise
        self._diag_timer = self._diagnostics_timer()
        # ~/latest_camera_info holds an estimate until the gate closes on it (a run-time
        # focal_range or max_uncertainty, a window that lost its focal): then a late joiner must
        # get nothing. The estimator thread signals it; the executor swaps the publisher.
        self._withdraw_signal = self.create_guard_condition(self._withdraw_latched)
        self._warn_unknown_overrides()
        self.worker.start()
        self.get_logger().info(
            f"fcop_node ready: inputs {[s.topic_name for s in self._subs]}, camera_info_in "
            f"{self.sub_info_in.topic_name}, sync {self.p['sync_mode']}, "
            f"window {self.p['window_frames']} frames"
        )

    def _create_topics(self) -> None:
        """Subscriptions and publishers; a QoS override (a parameter rclpy declares as each is
        created) the node cannot run with is a ParameterError naming it."""
        for topic in (*INPUTS, CAMERA_INFO_IN):
            self._check_qos_overrides(topic, "subscription")
        for topic in OUTPUTS:
            self._check_qos_overrides(topic, "publisher")
        try:
            self._create_topics_unchecked()
        except (ParameterException, InvalidQosOverridesError) as exc:
            raise ParameterError(f"QoS override refused: {exc}") from None
        except RuntimeError as exc:  # rclpy's words for a policy it does not know
            if "QoS override" not in str(exc):
                raise
            raise ParameterError(f"QoS override refused: {exc}") from None

    def _check_qos_overrides(self, topic: str, kind: str) -> None:
        """ParameterError for a QoS override of this topic's ``kind`` ('subscription' or
        'publisher') that rclpy would refuse with a traceback."""
        prefix = f"qos_overrides.{self.resolve_topic_name(topic)}.{kind}."
        problem = refused_override(node_parameters.given(self), prefix)
        if problem:
            raise ParameterError(problem)

    def _create_topics_unchecked(self) -> None:
        # Each topic gets a profile of its own (see .qos).
        qos_in = QoSOverridingOptions.with_default_policies()
        self._subs = [
            self.create_subscription(
                Image,
                name,
                lambda msg, i=i: self._on_image(i, msg),
                input_qos(),
                qos_overriding_options=qos_in,
            )
            for i, name in enumerate(INPUTS)
        ]
        self.sub_info_in = self.create_subscription(
            CameraInfo,
            CAMERA_INFO_IN,
            self._on_camera_info_in,
            input_qos(),
            qos_overriding_options=qos_in,
        )
        qos_out = QoSOverridingOptions.with_default_policies()
        # The outputs by their topic's relative name (as OUTPUTS writes them), for the tools.
        self.outputs = {
            topic: self.create_publisher(cls, topic, output_qos(), qos_overriding_options=qos_out)
            for topic, cls in OUTPUTS.items()}
        self.pub_info = self.outputs["camera_info"]
        self.pub_poses = self.outputs["object_poses"]
        self.pub_markers = self.outputs["object_markers"]
        self.pub_latest = self._latched_publisher()
        self.pub_diag = self.create_publisher(DiagnosticArray, "/diagnostics", 10)

    def _set_camera_info_client(self):
        """The client of set_camera_info_service (None for ''); a name ROS cannot take is a
        ParameterError in rclpy's words."""
        name = self.p["set_camera_info_service"]
        if not name:
            return None
        try:
            return self.create_client(SetCameraInfo, name)
        except (InvalidServiceNameException, ValueError) as exc:
            # rclpy's words: a name it cannot take, or a substitution ({bad}) it does not know
            why = str(exc).splitlines()[0].removeprefix("Invalid service name: ").rstrip(":")
            why = why.split(", at /")[0]  # rcl's source location
            raise ParameterError(not_allowed("set_camera_info_service", name,
                                             f"a service name ({why})")) from None

    # ----- parameters
    def _warn_unknown_overrides(self) -> None:
        """Name each parameter given (``-p``, a params file) that the node does not have: rclpy
        ignores it without a word, and a misspelt name would leave its default in force."""
        for name in sorted(node_parameters.given(self)):
            if not self.has_parameter(name):
                self.get_logger().warning(
                    f"parameter {name} is not one of this node's; ignored"
                    f"{self._unknown_parameter_hint(name)}"
                )

    def _unknown_parameter_hint(self, name: str) -> str:
        topics = sorted(s.topic_name for s in self._subs + [self.sub_info_in]) + [
            p.topic_name for p in self.outputs.values()]
        return node_parameters.unknown_hint(name, topics)

    def _before_set(self, params) -> list:
        """Before rclpy checks a set request: name a parameter the node does not have (rclpy
        refuses it with "Invalid access to undeclared parameter(s): []", naming none), and take
        an integer set for a double parameter as that double, as at start-up."""
        for prm in params:
            if not self.has_parameter(prm.name):
                self._throttle.warn(
                    "unknown_parameter",
                    f"cannot set parameter {prm.name}: not one of this node's"
                    f"{self._unknown_parameter_hint(prm.name)}")
        return node_parameters.as_requested(params)

    def _on_set_parameters(self, params) -> SetParametersResult:
        """rclpy has applied the descriptors (type, range, read-only); refuse what they cannot
        express (a choice among words, a text rule, rules between parameters), then apply."""
        new = dict(self.p)
        try:
            for prm in params:
                if prm.name in PARAMETERS:
                    check_words(prm.name, prm.value)
                    new[prm.name] = prm.value
        except ParameterError as exc:
            return SetParametersResult(successful=False, reason=str(exc))
        problem = check_combination(new, self.tracker.size, {prm.name for prm in params})
        if problem:
            return SetParametersResult(successful=False, reason=problem)
        changed = {k for k in new if new[k] != self.p.get(k)}
        with self._lock:
            self.p = new
            if changed & SYNC_PARAMETERS:
                self.ledger.dropped.update(self.intake.configure(*sync_settings(new)))
            if changed & ESTIMATOR_PARAMETERS:
                self.estimator_options = estimator_options(new)
            if changed & (WINDOW_PARAMETERS | GATE_PARAMETERS):
                self.tracker.configure(window_options(new), *gate_settings(new))
                if self.tracker.publishable is None:
                    self._withdraw_signal.trigger()
        if "diagnostics_period" in changed:
            self.destroy_timer(self._diag_timer)
            self._diag_timer = self._diagnostics_timer()
        return SetParametersResult(successful=True)

    def _new_sync(self) -> StampSynchronizer:
        return StampSynchronizer(len(INPUTS), *sync_settings(self.p))

    @property
    def received(self) -> int:
        """Input messages taken, all inputs together."""
        return sum(self.intake.received)

    @property
    def sync(self) -> StampSynchronizer:
        """The stamp synchroniser of the three inputs (under the node's lock)."""
        return self.intake.sync

    @property
    def window(self):
        """The FocalWindow (read it under the node's lock, or through window_estimate)."""
        return self.tracker.window

    def _reset_locked(self) -> None:
        self.tracker.reset()
        self.ledger.window_emptied()
        self.worker.clear()

    def _camera_info(self, focal: float, w: int, h: int, header):
        """The CameraInfo at ``focal`` for a w x h image, or IntrinsicsRefused."""
        return camera_info_with(focal, intrinsics(self.p, self._cam_in, w, h), w, h, header)

    def _on_camera_info_in(self, msg: CameraInfo) -> None:
        bad = [name for name, values in (("K", msg.k), ("D", msg.d), ("R", msg.r), ("P", msg.p))
               if not np.all(np.isfinite(np.asarray(values, dtype=np.float64)))]
        if bad:  # the output would carry them: keep the driver's last good message
            self._reject("camera_info_in_not_finite")
            self._throttle.warn(
                "camera_info_in_not_finite",
                f"ignored a camera_info_in message: its {', '.join(bad)} hold NaN or "
                "inf values; the last good one, if any, stays in use")
            return
        with self._lock:
            self._cam_in = msg
        raw = raw_camera(msg)
        if raw and not self._warned_distortion:
            self._warned_distortion = True
            self.get_logger().warning(
                f"camera_info_in describes a raw camera ({raw}): fCOP assumes a "
                "pinhole camera, so feed it rectified images; the output describes them, as "
                "REP-104's P does (principal point from P, D zero, R the identity)"
            )

    # ----- input side: cheap, never waits for the estimator
    def _on_image(self, index: int, msg: Image) -> None:
        with self._lock:
            step = self.intake.add(index, stamp_ns(msg), msg, self._now())
            if step.jumped:  # before the new frames reach the worker
                self._reset_locked()
            self.ledger.dropped.update(step.dropped)
            self._hand_off(step.sets)
        if step.jumped:
            self.info_out.forget()
        for _, msgs in step.sets:
            self._check_frame_ids(msgs)
        for i, stamp, m in step.accepted:
            if i == 0 and self._readable_depth(m):
                self.info_out.answer_depth(stamp, m, lambda: self.tracker.publishable)
        self._say(step.log)

    def _readable_depth(self, msg: Image) -> bool:
        """Whether depth image ``msg`` can be read; one that cannot gets no CameraInfo (its
        frame, if it matches, is dropped as bad_encoding when estimated), counted and said."""
        try:
            check_image(msg, DEPTH_ENCODINGS, "depth")
        except ImageFormatError as exc:
            with self._lock:
                self.ledger.warnings["depth_unreadable"] += 1
            self._throttle.warn("depth_unreadable", f"no CameraInfo for an unreadable {exc}")
            return False
        return True

    def _say(self, log) -> None:
        """Log (level 'warn' or 'info', key, line) entries, throttled by key and the line's
        words: a resize or a zoom is said at once, but two cameras on one topic, alternating
        sizes, said it for every frame."""
        for level, key, text in log:
            (self._throttle.warn if level == "warn" else self._throttle.info)(key, text)

    def _hand_off(self, sets) -> None:
        """Give the worker each matched frame (under self._lock); a frame it had not taken yet
        is replaced and counted."""
        for k, item in enumerate(sets):
            if not self.worker.put(item):
                continue
            self.ledger.dropped["estimator_busy"] += 1
            if k == 0:
                self._throttle.warn(
                    "estimator_busy",
                    "the estimator is slower than the input: skipped a frame (it "
                    "works on the newest one)",
                )
            else:  # replaced by its own batch, however fast the estimator is
                self._throttle.info(
                    "sets_at_once",
                    f"{len(sets)} frames matched at once (held messages released, "
                    "e.g. after a time jump); the estimator takes the newest",
                )

    def _check_frame_ids(self, msgs) -> None:
        """Count and warn (the outputs use the depth image's frame_id) where a frame's inputs
        leave it empty, name different frames, or both."""
        ids = [m.header.frame_id for m in msgs]
        reasons = [r for r, bad in (("frame_id_empty", not all(ids)),
                                    ("frame_id_mismatch", len({i for i in ids if i}) > 1)) if bad]
        if not reasons:
            return
        with self._lock:
            self.ledger.warnings.update(reasons)
        self._throttle.warn(
            reasons[0],
            "the inputs of one frame name different or empty frame_ids ("
            + ", ".join(f"{n} {i!r}" for n, i in zip(INPUTS, ids))
            + "): the outputs use the depth image's",
        )

    def _send_camera_info(self, info: CameraInfo) -> None:
        """One CameraInfo out, to camera_info and ~/latest_camera_info (under info_out's lock)."""
        self.pub_info.publish(info)
        self.pub_latest.publish(info)

    # ----- worker thread: conversions, estimation, poses
    def _estimate_item(self, item, generation: int) -> None:
        stamp, msgs = item
        self.process(stamp, msgs, generation)

    def _warm_up_kernels(self) -> None:
        """Compile the estimator's kernels (or load them from numba's cache) before the first
        frame; where they cannot be compiled, the numpy paths serve. /diagnostics says so
        meanwhile (a first run on a machine compiles for up to a minute). After Ctrl-C the
        context is gone and the outcome is not logged. The lines go to the console only: from
        this thread a rosout publish can race a Ctrl-C's shutdown between the check and the
        publish, and rcl then prints "Failed to publish log message to rosout" (seen once in
        CI); /diagnostics carries the kernels' state."""
        log = rclpy.logging.get_logger(f"{self.get_logger().name}.kernels")  # not on rosout
        if compiled.ENABLED:
            log.info(
                "preparing the estimator's kernels (the first run on a machine "
                "compiles them, up to a minute; later runs load them from the cache)"
            )
        t0 = time.perf_counter()
        try:
            seconds = compiled.warm_up()
        except Exception as exc:  # noqa: BLE001 - any compiler failure leaves numpy working
            compiled.ENABLED = False
            if self.context.ok():
                log.warning(
                    f"the compiled kernels failed to build ({exc!r}); estimating "
                    "with numpy, several times slower"
                )
        else:
            if compiled.ENABLED and self.context.ok():
                log.info(
                    f"estimator kernels ready ({compiled.describe()}, {seconds:.1f} s)"
                )
        finally:
            self.warm_up_seconds = time.perf_counter() - t0
            self._warming_up = False

    def _on_worker_error(self, item, exc: Exception) -> None:
        """The node must outlive any single bad frame: count it and say which. A frame that
        outlived destroy_node's wait fails on the destroyed handles, and one in progress when
        Ctrl-C shut the context down on its publishers: nothing to say then."""
        if self.worker.stopping or not self.context.ok():
            return
        why = f"failed: {type(exc).__name__}: {exc}"
        with self._lock:  # a frame without a focal, as one the estimator refused
            self.ledger.no_focal("exception", why)
        self._throttle.warn("exception", f"frame {item[0]} {why}")
        if not self._traceback_said:  # once: what a bug report needs
            self._traceback_said = True
            self.get_logger().warning(
                "the first failed frame's traceback (please report it):\n"
                + "".join(traceback.format_exception(exc)).rstrip())

    def _reject(self, reason: str, n: int = 1) -> None:
        """Count dropped input; the worker and the executor thread both do, diagnostics reads."""
        with self._lock:
            self.ledger.dropped[reason] += n

    def _refuse_frame(self, reason: str, why: str) -> bool:
        """Count a frame the estimator took but could not use (``reason``), log ``why`` with a
        throttle, and keep it as the newest frame's reason; returns False."""
        with self._lock:
            self.ledger.no_focal(reason, f"dropped: {why}")
        self._throttle.warn(reason, f"dropped frame: {why}")
        return False

    def idle(self) -> bool:
        """True when no frame is waiting or being estimated (used by replay and tests)."""
        return self.worker.idle()

    @property
    def warming_up(self) -> bool:
        """True while the worker prepares the estimator's kernels, before its first frame (a
        first run on a machine compiles them: a minute or more on a busy core)."""
        return self._warming_up

    @property
    def processed(self) -> int:
        """Frames the estimator finished (failed ones included)."""
        return self.worker.processed

    @property
    def processing_seconds(self) -> tuple:
        """Wall time of the last (up to 200) processed frames: conversion, estimate, window."""
        with self._lock:
            return tuple(self.ledger.processing_seconds)

    @property
    def latest(self) -> LatestEstimate | None:
        """The last CameraInfo publication and the estimate behind it (None before the first)."""
        return self.info_out.latest

    @property
    def window_estimate(self):
        """The focal window's current WindowEstimate (whether or not within max_uncertainty)."""
        with self._lock:
            return self.window.current

    @property
    def counts(self) -> NodeCounts:
        """The node's counters, read together."""
        with self._lock:
            return NodeCounts(
                self.received,
                self.sync.stats.matched,
                self.worker.processed,
                self.ledger.frames_published,
                self.ledger.skipped,
                self.info_out.published,
                Counter(self.ledger.dropped),
                Counter(self.ledger.warnings),
            )

    def process(self, stamp: int, msgs, generation: int | None = None) -> bool:
        """Estimate one synchronised frame, update the window and publish the frame's poses and
        markers; returns True when the window has a publishable estimate afterwards."""
        t0 = time.perf_counter()
        depth_msg = msgs[0]
        p = self.p
        with self._lock:
            camera_info_in = self._cam_in
        try:
            est = estimate_frame(msgs, p, camera_info_in, self.estimator_options, self._rng)
        except Refused as exc:
            return self._refuse_frame(exc.reason, str(exc))
        with self._lock:
            if generation is not None and generation != self.worker.generation:
                return False  # taken before a reset
            step = self.tracker.add(est, stamp * 1e-9, depth_msg.header.frame_id)
            self.last_estimate = est
            said = frame_outcome(est, step, depth_msg.header.frame_id)
            self.ledger.estimated(est, said, time.perf_counter() - t0)
        self._say(said.log)
        ready = step.ready
        if ready is None and self.info_out.latest is not None:
            self._withdraw_signal.trigger()
        if not said.kept or ready is None:
            return False
        # This frame's depth image arrived before there was an estimate: answer it now.
        self.info_out.answer_owed(stamp, depth_msg.header, ready)
        objects = []
        if p["publish_poses"] or p["publish_markers"]:
            # Poses at the window's focal length: steadier than the frame's own.
            objects = (estimate_poses(est.instances, ready.focal, exclude=est.mirrored)
                       if est.focal is not None else [])
            poses = object_poses(objects)  # one quaternion conversion for both messages
            if p["publish_poses"]:
                self.pub_poses.publish(pose_array(objects, depth_msg.header, poses))
            if p["publish_markers"]:
                self.pub_markers.publish(marker_array(objects, depth_msg.header, poses=poses))
        self.info_out.objects(stamp, objects)
        with self._lock:
            self.ledger.frames_published += 1
        return True

    # ----- services
    def _latched_publisher(self):
        return self.create_publisher(CameraInfo, "~/latest_camera_info", latched_qos())

    def _renew_latched(self) -> None:
        """A new ~/latest_camera_info publisher in place of the old (under info_out's lock):
        late joiners get nothing from before it."""
        self.destroy_publisher(self.pub_latest)
        self.pub_latest = self._latched_publisher()

    def _withdraw_latched(self) -> None:
        """If the gate has closed on what ~/latest_camera_info holds, a new publisher: late
        joiners then get nothing, as they would after ~/reset (run by the executor)."""
        with self.info_out.lock:
            if self.info_out.latest is None or self.tracker.publishable is not None:
                return
            self._renew_latched()
            self.info_out.withdraw()
        self._throttle.info("latest_withdrawn", "~/latest_camera_info withdrawn: "
                            + (self.tracker.held_back() or "no publishable focal"))

    def _on_reset(self, request, response):
        with self._lock:
            self._reset_locked()
            self.intake.reset()
            self.last_estimate = None
        with self.info_out.lock:
            self._renew_latched()
            # In the same step: a frame taken before the reset finds its stamp gone.
            self.info_out.clear()
        response.success = True
        response.message = ("focal window, synchroniser, hand-off, latest_camera_info and "
                            "the latest estimate cleared")
        self._throttle.info("reset", "reset by service")
        return response

    def calibration_path(self) -> str:
        """Where ~/save_calibration writes (see :func:`.calibration.calibration_path`)."""
        return calibration_path(self.p["calibration_file"], self.p["camera_name"])

    def _on_save_calibration(self, request, response):
        with self._lock:
            est, why = self.tracker.publishable, self.tracker.held_back()
            p = dict(self.p)
        response.success = False
        if est is None:
            response.message = why or "no image yet"
            self.get_logger().warning(f"calibration not saved: {response.message}")
            return response
        try:
            with self._lock:
                # A driver stores its calibration at full resolution (REP-104).
                info = at_full_resolution(
                    self._camera_info(est.focal, est.width, est.height, None), self._cam_in)
        except IntrinsicsRefused as exc:
            response.message = str(exc)
            return response
        response.success, response.message = save_calibration(
            info, est.std_rel, calibration_path(p["calibration_file"], p["camera_name"]),
            p["camera_name"])
        if not response.success:
            self.get_logger().error(f"calibration not saved: {response.message}")
            return response
        if self.set_info_client is not None:
            if self.set_info_client.service_is_ready():
                self.set_info_client.call_async(
                    SetCameraInfo.Request(camera_info=info)
                ).add_done_callback(self._on_set_camera_info_done)
                response.message += (f"; asked {self.set_info_client.srv_name} to store it (its "
                                     "answer is logged, and a refusal counted in /diagnostics)")
            else:
                response.message += f"; {self.set_info_client.srv_name} is not available"
        self.get_logger().info(response.message)
        return response

    def _on_set_camera_info_done(self, future) -> None:
        res = future.result()
        if res is None or not res.success:
            with self._lock:
                self.ledger.warnings["set_camera_info_refused"] += 1
            self.get_logger().error(
                f"{self.set_info_client.srv_name} refused the calibration: "
                f"{getattr(res, 'status_message', 'no answer')}"
            )
        else:
            self.get_logger().info(
                f"{self.set_info_client.srv_name} took the calibration"
            )

    # ----- diagnostics
    def diagnostic_status(self) -> DiagnosticStatus:
        """The node's status now (what publish_diagnostics sends); see :mod:`.diagnostics`."""
        now = self._now()
        with self._lock:  # the worker thread updates these while we read
            work = self.worker.state()
            ready, no_camera_info = self.tracker.publishable, ""
            if ready is not None:
                try:
                    intrinsics(self.p, self._cam_in, ready.width, ready.height)
                except IntrinsicsRefused as exc:
                    no_camera_info = str(exc)
            reading = DiagnosticsInput(
                now=now,
                window_estimate=self.window.current,
                publishable=ready is not None,
                window_fill=f"{len(self.window)}/{self.p['window_frames']}",
                max_uncertainty=self.p["max_uncertainty"],
                focal_range=gate_settings(self.p)[1],
                max_estimate_age=self.p["max_estimate_age"],
                matched=self.sync.stats.matched,
                processed=work.processed,
                skipped=self.ledger.skipped,
                sync_dropped=self.sync.stats.dropped_total,
                camera_info_published=self.info_out.published,
                busy_for=None if work.busy_since is None else now - work.busy_since,
                age=None if work.last_done is None else now - work.last_done,
                processing_ms=tuple(t * 1000 for t in self.ledger.processing_seconds),
                dropped=dict(self.ledger.dropped),
                warnings=dict(self.ledger.warnings),
                kernels=compiled.describe(),
                warming_up=self._warming_up,
                last_reason=self.ledger.newest_refusal,
                since_empty=self.ledger.since_empty,
                no_camera_info=no_camera_info,
                input_ages=self.intake.ages(now),
                since_first_input=self.intake.since_first(now),
                queue_advice=self.intake.queue_advice(),
            )
            inputs = tuple(self.intake.received)
            no_focal = self.ledger.no_focal_frames
        rates = self._rates.add(now, reading.matched, reading.processed, reading.skipped,
                                reading.camera_info_published, no_focal, inputs, reading.dropped)
        return diagnostic_status(
            f"{self.get_name()}: focal estimate", self.get_fully_qualified_name(), reading, rates
        )

    def _diagnostics_timer(self):
        """Every diagnostics_period of wall time (steady clock), as the rates and ages it reports
        are: under use_sim_time the node's clock stops with /clock, and health reports must
        not (a stalled bag or simulator is what they should show)."""
        return self.create_timer(float(self.p["diagnostics_period"]), self.publish_diagnostics,
                                 clock=Clock(clock_type=ClockType.STEADY_TIME))

    def publish_diagnostics(self) -> DiagnosticArray:
        msg = DiagnosticArray()
        msg.header.stamp = self.get_clock().now().to_msg()
        msg.status = [self.diagnostic_status()]
        self.pub_diag.publish(msg)
        self._log_health(msg.status[0])
        return msg

    def _log_health(self, status: DiagnosticStatus) -> None:
        """Say /diagnostics' news in the log too (see :class:`.diagnostics.HealthNews`)."""
        news = self._health_news(status.level, status.message)
        if news is None:
            return
        level, text = news
        if level == DiagnosticStatus.OK:
            self.get_logger().info(text)
        elif level == DiagnosticStatus.ERROR:
            self.get_logger().error(text)
        else:
            self._throttle.warn("health", text)

    def destroy_node(self):
        if self.worker is not None:
            self.worker.stop(timeout=5.0)
        return super().destroy_node()


def main(args=None) -> int:
    """Entry point of ``ros2 run fcop_ros fcop_node``: spin until Ctrl-C or external shutdown.
    Exit codes: 0 after a clean shutdown (and for ``--help``), 2 for a parameter it cannot run
    with (one line on stderr)."""
    argv = sys.argv if args is None else args
    if wants_help(argv):
        print(USAGE)
        return 0
    limit_allocator_arenas()  # before the node's threads: no step growth over long runs
    problem = params_file_problem(argv)
    if problem:  # before rcl, which logs a line of its own and raises
        print(f"fcop_node: {problem}", file=sys.stderr)
        return 2
    try:
        rclpy.init(args=args)
    except RCLError as exc:  # rcl parses the ROS arguments here: -p, --params-file, -r, ...
        print(f"fcop_node: {rcl_params_error(exc)}", file=sys.stderr)
        return 2
    node = None
    try:
        # The executor exists before the node logs "ready", so an early Ctrl-C finds it whole.
        executor = SingleThreadedExecutor()
        node = FcopNode()
        executor.add_node(node)
        executor.spin()
    except ParameterError as exc:
        print(f"fcop_node: {exc}", file=sys.stderr)
        return 2
    except ParameterException as exc:  # rclpy's own parameters, e.g. use_sim_time: 1
        print(f"fcop_node: parameter not allowed: {exc}", file=sys.stderr)
        return 2
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except RCLError:
        # Ctrl-C or SIGTERM while the node was being built: rclpy's signal handler shut the
        # context down under it, and rcl refuses the next entity. A clean stop, not a crash.
        if rclpy.ok():
            raise
    finally:
        if node is not None:
            node.destroy_node()
        shut_down()  # a Ctrl-C's handler may be shutting it down at the same moment
    return 0


if __name__ == "__main__":  # python -m: as the console script, signals included
    from fcop_ros.entry_points import fcop_node

    raise SystemExit(fcop_node())
