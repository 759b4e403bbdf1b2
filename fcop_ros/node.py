"""fcop_node: live focal length from depth, NOCS and instance-mask images.

A thin shell around :mod:`fcop_ros.core`: it converts messages (msg_adapters), synchronises
them by stamp (:mod:`fcop_ros.sync`), hands matched frames to a worker thread through a
bounded drop-oldest queue (heavy work never runs in a subscription callback), feeds each
frame's evidence to the sliding window and publishes CameraInfo, poses and markers once the
window has evidence. Nothing is published for a frame without evidence.
"""
from __future__ import annotations

import math
import threading
import time
from collections import Counter, deque

import numpy as np
import rclpy
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import PoseArray
from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor, SetParametersResult
from rclpy.node import Node
from rclpy.qos import (DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy, qos_profile_sensor_data,
                       qos_profile_system_default)
from rclpy.qos_overriding_options import QoSOverridingOptions
from sensor_msgs.msg import CameraInfo, Image
from std_srvs.srv import Trigger
from visualization_msgs.msg import MarkerArray

from msg_adapters import (ImageFormatError, camera_info, depth_from_image, marker_array, mask_from_image,
                          nocs_from_image, object_poses, pose_array, stamp_ns)

from .core import FocalWindow, estimate_focal
from .sync import StampSynchronizer

INPUTS = ("depth", "nocs", "mask")

# name: (default, description, (min, max) or choices or None)
PARAMETERS = {
    "window_frames": (30, "Frames in the sliding window of focal evidence.", (1, 1000)),
    "window_seconds": (0.0, "Also forget frames older than this many seconds (0 = no age limit).", (0.0, 3600.0)),
    "triplets_per_object": (1500, "Random triplets drawn on each object per frame.", (10, 100000)),
    "noise_bound": (0.05, "Stabbing half-width: a fraction of f (relative mode) or pixels (absolute).",
                    (1e-4, 1000.0)),
    "noise_bound_mode": ("relative", "'relative' (log f, same meaning at every focal) or 'absolute' (pixels).",
                         ("relative", "absolute")),
    "focal_min": (50.0, "Smallest focal length considered, pixels.", (1.0, 1e6)),
    "focal_max": (20000.0, "Largest focal length considered, pixels.", (1.0, 1e6)),
    "min_object_pixels": (50, "Instances with fewer usable pixels are ignored.", (3, 10000000)),
    "depth_scale": (0.001, "Metres per unit of 16UC1 depth images (REP-118: millimetres).", (1e-9, 1000.0)),
    "principal_point_x": (-1.0, "cx in pixels; negative = image centre (W-1)/2.", (-1.0, 1e6)),
    "principal_point_y": (-1.0, "cy in pixels; negative = image centre (H-1)/2.", (-1.0, 1e6)),
    "sync_mode": ("exact", "'exact' (equal stamps) or 'approximate' (within sync_slop).", ("exact", "approximate")),
    "sync_slop": (0.01, "Largest stamp difference within a frame in approximate mode, seconds.", (0.0, 1.0)),
    "queue_size": (5, "Messages per input waiting for a match, and frames waiting for the estimator.", (1, 100)),
    "publish_poses": (True, "Publish object_poses (geometry_msgs/PoseArray).", None),
    "publish_markers": (True, "Publish object_markers (visualization_msgs/MarkerArray).", None),
    "min_frames": (1, "Frames the window needs before it reports a focal length.", (1, 1000)),
    "min_support": (30, "Agreeing triplet votes the window needs before it reports a focal length.", (1, 10000000)),
    "diagnostics_period": (1.0, "Seconds between /diagnostics messages.", (0.05, 60.0)),
    "seed": (-1, "Random seed of triplet sampling (-1 = from the OS).", (-1, 2 ** 31 - 1)),
}


def _descriptor(name, default, description, limits):
    d = ParameterDescriptor(name=name, description=description)
    if isinstance(limits, tuple) and len(limits) == 2 and not isinstance(limits[0], str):
        if isinstance(default, bool):
            pass
        elif isinstance(default, int):
            d.integer_range = [IntegerRange(from_value=int(limits[0]), to_value=int(limits[1]), step=1)]
        else:
            d.floating_point_range = [FloatingPointRange(from_value=float(limits[0]), to_value=float(limits[1]))]
    elif isinstance(limits, tuple):
        d.additional_constraints = "one of: " + ", ".join(limits)
    return d


class _Throttle:
    """At most one log line per reason every ``period`` seconds, with the count since the last."""

    def __init__(self, logger, period: float = 5.0):
        self.logger, self.period = logger, period
        self._last: dict[str, float] = {}
        self._since: Counter = Counter()

    def warn(self, reason: str, text: str) -> None:
        self._since[reason] += 1
        now = time.monotonic()
        if now - self._last.get(reason, -math.inf) >= self.period:
            n = self._since.pop(reason)
            self._last[reason] = now
            self.logger.warning(f"{text}" + (f" ({n} such since the last report)" if n > 1 else ""))


class FcopNode(Node):
    """The fcop_node ROS 2 node (see the package README for topics and parameters)."""

    def __init__(self, node_name: str = "fcop_node", **kwargs):
        super().__init__(node_name, **kwargs)
        for name, (default, text, limits) in PARAMETERS.items():
            self.declare_parameter(name, default, _descriptor(name, default, text, limits))
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self.p = {name: self.get_parameter(name).value for name in PARAMETERS}
        problem = self._check(self.p)
        if problem:
            raise ValueError(f"fcop_node: invalid parameters: {problem}")

        self.rejected: Counter = Counter()
        self.last = None  # (stamp ns, WindowEstimate, published ObjectPoses, CameraInfo) of the last publication
        self.received = 0
        self.processed = 0
        self.published = 0
        self.handoff_dropped = 0
        self._proc_times: deque = deque(maxlen=200)
        self._arrivals: deque = deque(maxlen=200)
        self._throttle = _Throttle(self.get_logger())
        self._lock = threading.Lock()
        self._cv = threading.Condition(self._lock)
        self._frames: deque = deque()
        self._busy = False
        self._stop = False
        self._rng_seed = None if self.p["seed"] < 0 else int(self.p["seed"])
        self._rng = np.random.default_rng(self._rng_seed)
        self._build_sync()
        self._build_window()

        qos_in = QoSOverridingOptions.with_default_policies()
        self._subs = [
            self.create_subscription(Image, name, lambda msg, i=i: self._on_image(i, msg), qos_profile_sensor_data,
                                     qos_overriding_options=qos_in)
            for i, name in enumerate(INPUTS)
        ]
        qos_out = QoSOverridingOptions.with_default_policies()
        self.pub_info = self.create_publisher(CameraInfo, "camera_info", qos_profile_system_default,
                                              qos_overriding_options=qos_out)
        self.pub_poses = self.create_publisher(PoseArray, "object_poses", qos_profile_system_default,
                                               qos_overriding_options=qos_out)
        self.pub_markers = self.create_publisher(MarkerArray, "object_markers", qos_profile_system_default,
                                                 qos_overriding_options=qos_out)
        latched = QoSProfile(depth=1, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self.pub_latest = self.create_publisher(CameraInfo, "~/latest_camera_info", latched)
        self.pub_diag = self.create_publisher(DiagnosticArray, "/diagnostics", 10)
        self.srv_reset = self.create_service(Trigger, "~/reset", self._on_reset)
        self._diag_timer = self.create_timer(float(self.p["diagnostics_period"]), self.publish_diagnostics)
        self._worker = threading.Thread(target=self._work, name="fcop_estimator", daemon=True)
        self._worker.start()
        self.get_logger().info(
            f"fcop_node ready: inputs {[s.topic_name for s in self._subs]}, sync {self.p['sync_mode']}, "
            f"window {self.p['window_frames']} frames")

    # ----- parameters
    @staticmethod
    def _check(p: dict) -> str:
        if p["focal_min"] >= p["focal_max"]:
            return f"focal_min ({p['focal_min']}) must be below focal_max ({p['focal_max']})"
        for name in ("noise_bound_mode", "sync_mode"):
            choices = PARAMETERS[name][2]
            if p[name] not in choices:
                return f"{name} must be one of {choices}, got {p[name]!r}"
        if p["noise_bound_mode"] == "relative" and not 0 < p["noise_bound"] <= 0.5:
            return f"noise_bound {p['noise_bound']} is not a fraction in (0, 0.5] (relative mode)"
        return ""

    def _on_set_parameters(self, params) -> SetParametersResult:
        new = dict(self.p)
        for prm in params:
            if prm.name not in PARAMETERS:
                continue
            default = PARAMETERS[prm.name][0]
            value = prm.value
            if isinstance(default, float) and isinstance(value, int) and not isinstance(value, bool):
                value = float(value)
            if type(value) is not type(default):
                return SetParametersResult(successful=False,
                                           reason=f"{prm.name} must be {type(default).__name__}, got {value!r}")
            lim = PARAMETERS[prm.name][2]
            if isinstance(lim, tuple) and len(lim) == 2 and not isinstance(lim[0], str) \
                    and not isinstance(value, bool) and not lim[0] <= value <= lim[1]:
                return SetParametersResult(successful=False,
                                           reason=f"{prm.name}={value} is outside [{lim[0]}, {lim[1]}]")
            new[prm.name] = value
        problem = self._check(new)
        if problem:
            return SetParametersResult(successful=False, reason=problem)
        changed = {k for k in new if new[k] != self.p.get(k)}
        with self._lock:
            self.p = new
            if changed & {"sync_mode", "sync_slop", "queue_size"}:
                self._build_sync()
            if changed & {"window_frames", "window_seconds", "noise_bound", "noise_bound_mode", "min_frames",
                          "min_support"}:
                self._build_window()
            if "seed" in changed:
                self._rng = np.random.default_rng(None if new["seed"] < 0 else int(new["seed"]))
        return SetParametersResult(successful=True)

    def _build_sync(self) -> None:
        slop = self.p["sync_slop"] if self.p["sync_mode"] == "approximate" else 0.0
        self.sync = StampSynchronizer(len(INPUTS), self.p["queue_size"], slop)

    def _build_window(self) -> None:
        self.window = FocalWindow(max_frames=self.p["window_frames"], max_age=self.p["window_seconds"] or None,
                                  min_frames=self.p["min_frames"], min_support=self.p["min_support"])

    # ----- input side: cheap, never blocks on the estimator
    def _on_image(self, index: int, msg: Image) -> None:
        stamp = stamp_ns(msg)
        with self._lock:
            self.received += 1
            before = Counter(self.sync.stats.dropped)
            resets = self.sync.stats.resets
            sets = self.sync.add(index, stamp, msg)
            new_drops = self.sync.stats.dropped - before
            jumped = self.sync.stats.resets != resets
            if jumped:  # before the new frames reach the worker
                self.window.reset()
                self.rejected["sync_time_jump_reset"] += len(self._frames)
                self._frames.clear()
            for stamp_set, msgs in sets:
                if len(self._frames) >= self.p["queue_size"]:
                    self._frames.popleft()
                    self.handoff_dropped += 1
                    self.rejected["estimator_busy"] += 1  # under self._lock here
                self._frames.append((stamp_set, msgs))
                self._arrivals.append(time.monotonic())
            if sets:
                self._cv.notify()
        if jumped:
            self._throttle.warn("time_jump", "fcop_node: time jumped back (looped bag?): synchroniser and "
                                             "window reset")
        for reason, n in new_drops.items():
            self._reject("sync_" + reason, n)
            if reason != "time_jump_reset":
                self._throttle.warn("sync_" + reason, f"fcop_node: dropped {n} input message(s) in the "
                                                      f"synchroniser: {reason.replace('_', ' ')}")

    # ----- worker thread: conversions, estimation, publishing
    def _work(self) -> None:
        while True:
            with self._cv:
                while not self._frames and not self._stop:
                    self._cv.wait(0.5)
                if self._stop:
                    return
                stamp, msgs = self._frames.popleft()
                self._busy = True
            try:
                self.process(stamp, msgs)
            except Exception as exc:  # the node must outlive any single bad frame
                self._reject("exception")
                self._throttle.warn("exception", f"fcop_node: frame {stamp} failed: {type(exc).__name__}: {exc}")
            finally:
                with self._lock:
                    self._busy = False
                    self.processed += 1

    def _reject(self, reason: str, n: int = 1) -> None:
        """Count dropped input; the worker and the executor thread both do, diagnostics reads."""
        with self._lock:
            self.rejected[reason] += n

    def idle(self) -> bool:
        """True when no frame is waiting or being estimated (used by replay and tests)."""
        with self._lock:
            return not self._frames and not self._busy

    def process(self, stamp: int, msgs) -> bool:
        """Estimate one synchronised frame and publish; returns True when something was published."""
        t0 = time.perf_counter()
        depth_msg, nocs_msg, mask_msg = msgs
        p = self.p
        try:
            depth = depth_from_image(depth_msg, p["depth_scale"])
            nocs = nocs_from_image(nocs_msg)
            mask = mask_from_image(mask_msg)
        except ImageFormatError as exc:
            self._reject("bad_encoding")
            self._throttle.warn("bad_encoding", f"fcop_node: rejected frame: {exc}")
            return False
        if not (depth.shape == nocs.shape[:2] == mask.shape):
            self._reject("size_mismatch")
            self._throttle.warn("size_mismatch", f"fcop_node: rejected frame: image sizes differ: depth "
                                                 f"{depth.shape[::-1]}, nocs {nocs.shape[1::-1]}, mask {mask.shape[::-1]}")
            return False
        h, w = depth.shape
        cx = p["principal_point_x"] if p["principal_point_x"] >= 0 else (w - 1) / 2.0
        cy = p["principal_point_y"] if p["principal_point_y"] >= 0 else (h - 1) / 2.0
        est = estimate_focal(depth, nocs, mask, (cx, cy), triplets_per_object=p["triplets_per_object"],
                             noise_bound=p["noise_bound"], bound_mode=p["noise_bound_mode"],
                             focal_range=(p["focal_min"], p["focal_max"]), min_object_pixels=p["min_object_pixels"],
                             poses=False, seed=int(self._rng.integers(2 ** 31)))
        if est.focal is None:
            self._reject("no_evidence")
            self._throttle.warn("no_evidence", f"fcop_node: frame without focal evidence: {est.reason}")
        with self._lock:
            win = self.window.add(est, stamp * 1e-9)
        if win.changed:
            self.get_logger().info(f"fcop_node: focal length changed (zoom?): window restarted at {win.focal}")
        with self._lock:
            self._proc_times.append(time.perf_counter() - t0)
        if win.focal is None:
            return False
        header = depth_msg.header
        info = camera_info(win.focal, cx, cy, w, h, header)
        self.pub_info.publish(info)  # first: the pose work below does not delay it
        self.pub_latest.publish(info)
        objects = []
        if p["publish_poses"] or p["publish_markers"]:
            # Poses at the window's focal length: steadier than the frame's own.
            objects = est.poses_at(win.focal) if est.focal is not None else []
            poses = object_poses(objects)  # one quaternion conversion for both messages
            if p["publish_poses"]:
                self.pub_poses.publish(pose_array(objects, header, poses))
            if p["publish_markers"]:
                self.pub_markers.publish(marker_array(objects, header, poses=poses))
        self.last = (stamp, win, objects, info)
        self.published += 1
        return True

    # ----- services and diagnostics
    def _on_reset(self, request, response):
        with self._lock:
            self.window.reset()
            self.sync.reset()
            self._frames.clear()
        response.success = True
        response.message = "focal window, synchroniser and queue cleared"
        self.get_logger().info("fcop_node: reset by service")
        return response

    def publish_diagnostics(self) -> None:
        win = self.window.current
        st = DiagnosticStatus()
        st.name = f"{self.get_name()}: focal estimate"
        st.hardware_id = self.get_fully_qualified_name()
        if win.focal is None:
            st.level, st.message = DiagnosticStatus.WARN, f"no focal estimate yet: {win.reason}"
        elif win.std_rel is None or win.std_rel > 0.05:
            st.level, st.message = DiagnosticStatus.WARN, f"focal {win.focal:.1f} px, uncertain (std_rel {win.std_rel})"
        else:
            st.level, st.message = DiagnosticStatus.OK, f"focal {win.focal:.1f} px"
        now = time.monotonic()
        with self._lock:  # the worker thread appends to these while we read
            arrivals = list(self._arrivals)
            times = np.array(self._proc_times) * 1000 if self._proc_times else np.zeros(1)
            rejected = dict(self.rejected)
        rate = sum(1 for t in arrivals if now - t <= 5.0) / 5.0
        values = {
            "focal_px": "" if win.focal is None else f"{win.focal:.3f}",
            "std_rel": "" if win.std_rel is None else f"{win.std_rel:.4f}",
            "support_votes": str(win.support),
            "window_fill": f"{len(self.window)}/{self.p['window_frames']}",
            "frame_rate_hz": f"{rate:.2f}",
            "frames_processed": str(self.processed),
            "camera_info_published": str(self.published),
            "sync_matched": str(self.sync.stats.matched),
            "sync_dropped": str(self.sync.stats.dropped_total),
            "processing_ms_median": f"{np.median(times):.2f}",
            "processing_ms_max": f"{np.max(times):.2f}",
        }
        values.update({f"rejected_{k}": str(v) for k, v in sorted(rejected.items())})
        st.values = [KeyValue(key=k, value=v) for k, v in values.items()]
        msg = DiagnosticArray()
        msg.header.stamp = self.get_clock().now().to_msg()
        msg.status = [st]
        self.pub_diag.publish(msg)

    def destroy_node(self):
        with self._cv:
            self._stop = True
            self._cv.notify_all()
        if self._worker.is_alive() and threading.current_thread() is not self._worker:
            self._worker.join(timeout=5.0)
        return super().destroy_node()


def main(args=None) -> int:
    """Entry point of ``ros2 run fcop_ros fcop_node``: spin until Ctrl-C or external shutdown."""
    rclpy.init(args=args)
    node = None
    try:
        # The executor exists before the node logs "ready", so an early Ctrl-C finds it whole.
        executor = SingleThreadedExecutor()
        node = FcopNode()
        executor.add_node(node)
        executor.spin()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        if node is not None:
            node.destroy_node()
        if rclpy.ok():
            rclpy.shutdown()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
