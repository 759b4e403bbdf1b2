"""fcop_node in-process: a private Context, the node and a test node in one executor, spun
until a condition holds with a deadline."""
import os
import time

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from scipy.spatial.transform import Rotation
from sensor_msgs.msg import CameraInfo, Image
from std_srvs.srv import Trigger
from visualization_msgs.msg import Marker

from fcop_ros.core import compiled
from fcop_ros.core.pose import rotation_angle_deg
from fcop_ros.synthetic.scenes import (BAD_CASES, camera_frame as cam, camera_frames, clean_frame,
                                       corrupted)
from msg_adapters import header_from_ns
from ros_helpers import Gate, Recorder, frame_messages, spin_until, stamp_ns

CONFIG = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "config",
                      "fcop.yaml")
T0 = 1_700_000_000_000_000_000
DT = 33_333_333


# Measured over this test's 12 moderate frames (seeds 0..11, f = 600 px, window of 30 frames,
# parameter seed 1): focal error of every published CameraInfo at most 2.5%, median object
# rotation error 0.47 deg, median translation error 4.3% of the distance (the preset's global
# depth scale error goes straight into translation). The bounds were set with margin on the
# figures of the presets before they became settings of the world's mechanisms (3.0%, 1.6 deg,
# 11%) and are kept.
FOCAL_BOUND = 0.045
ROT_MEDIAN_BOUND_DEG = 3.0
TRANS_MEDIAN_BOUND = 0.2


def test_camera_info_per_input_stamp_within_bound(harness):
    h = harness(parameter_overrides=[Parameter("seed", value=1)])
    frames = camera_frames(12, 600.0)
    sent = []
    for k, fr in enumerate(frames):
        stamp = T0 + k * DT
        h.send(frame_messages(fr, stamp))
        sent.append(stamp)
        assert spin_until(
            h.ex,
            lambda: len(h.info) >= k + 1 and len(h.poses) >= k + 1 and len(h.markers) >= k + 1,
            20,
        )
    assert [stamp_ns(m) for m in h.info.msgs] == sent
    assert len(h.poses) == len(h.markers) == len(sent)  # zip below must not drop any
    rot, trans = [], []
    for info, poses, markers, fr in zip(h.info.msgs, h.poses.msgs, h.markers.msgs, frames):
        # REP-104
        f = info.k[0]
        assert info.k[4] == f and info.width == 640 and info.height == 480
        assert info.k[2] == 319.5 and info.k[5] == 239.5
        assert abs(f / 600.0 - 1) < FOCAL_BOUND
        assert list(info.p) == [f, 0, 319.5, 0, 0, f, 239.5, 0, 0, 0, 1, 0]
        assert list(info.r) == [1, 0, 0, 0, 1, 0, 0, 0, 1]
        assert info.distortion_model == "plumb_bob" and list(info.d) == [0.0] * 5
        assert info.header.frame_id == "camera_optical_frame"
        assert stamp_ns(poses) == stamp_ns(info) == stamp_ns(markers.markers[0])
        assert markers.markers[0].action == Marker.DELETEALL
        assert len(markers.markers) == len(poses.poses) + 1 and len(poses.poses) >= 3
        truth = {o.instance_id: o for o in fr.objects}
        for pose, marker in zip(poses.poses, markers.markers[1:]):
            o = truth[marker.id]
            q = pose.orientation
            R = Rotation.from_quat([q.x, q.y, q.z, q.w]).as_matrix()
            rot.append(rotation_angle_deg(R, o.rotation))
            t = np.array([pose.position.x, pose.position.y, pose.position.z])
            trans.append(np.linalg.norm(t - o.translation) / np.linalg.norm(o.translation))
            assert marker.type == Marker.CUBE and marker.scale.x > 0
    assert np.median(rot) < ROT_MEDIAN_BOUND_DEG
    assert np.median(trans) < TRANS_MEDIAN_BOUND
    assert h.node.counts.dropped.total() == 0


def test_remapping_and_params_file(harness):
    h = harness(node_args=["--ros-args", "-r", "depth:=/cam/depth", "-r", "nocs:=/cam/nocs",
                           "-r", "mask:=/cam/mask", "-r", "camera_info:=/cam/camera_info_est",
                           "--params-file", CONFIG],
                inputs=("/cam/depth", "/cam/nocs", "/cam/mask"))
    assert [s.topic_name for s in h.node._subs] == ["/cam/depth", "/cam/nocs", "/cam/mask"]
    assert h.node.pub_info.topic_name == "/cam/camera_info_est"
    rec = Recorder(h.tester, CameraInfo, "/cam/camera_info_est")
    h.send(frame_messages(clean_frame(0), T0))
    assert spin_until(h.ex, lambda: len(rec) == 1, 20)
    assert abs(rec.msgs[0].k[0] / clean_frame(0).focal - 1) < 1e-3


def test_params_file_values_are_loaded(harness, tmp_path):
    text = open(CONFIG).read().replace("window_frames: 30", "window_frames: 7").replace(
        "sync_mode: exact", "sync_mode: approximate")
    path = tmp_path / "p.yaml"
    path.write_text(text)
    h = harness(node_args=["--ros-args", "--params-file", str(path)])
    assert h.node.get_parameter("window_frames").value == 7
    assert h.node.window.options.max_frames == 7 and h.node.sync.slop_ns == 10_000_000
    assert h.node.get_parameter("depth_scale").value == 0.001
    # Every parameter has a description, and numbers a range.
    for name in h.node.p:
        d = h.node.describe_parameter(name)
        assert d.description
        if isinstance(h.node.p[name], (int, float)) and not isinstance(h.node.p[name], bool):
            assert d.integer_range or d.floating_point_range


def test_runtime_parameter_changes(harness):
    h = harness()
    node = h.node
    ok = node.set_parameters([Parameter("window_frames", value=10),
                              Parameter("sync_mode", value="approximate"),
                              Parameter("sync_slop", value=0.02)])
    assert all(r.successful for r in ok)
    assert node.window.options.max_frames == 10 and node.sync.slop_ns == 20_000_000
    # Type and range: the descriptors, which rclpy applies before the node's callback runs.
    refused = (("window_frames", 0, "out of range"), ("focal_min", 0.5, "out of range"),
               ("queue_size", "five", "Wrong parameter type"))
    for name, value, reason in refused:
        res = node.set_parameters([Parameter(name, value=value)])[0]
        assert not res.successful and reason in res.reason, (name, res.reason)
    # What a descriptor cannot say, the node's own check, called as rclpy calls it.
    bad = {
        "noise_bound_mode": ("fuzzy", "one of relative, absolute"),  # not a choice
        "sync_mode": ("sometimes", "one of exact, approximate"),
        "focal_min": (30000.0, "below focal_max=20000.0"),       # above focal_max
        "noise_bound": (0.9, "(0, 0.5]"),                        # not a fraction in relative mode
    }
    for name, (value, allowed) in bad.items():
        res = node._on_set_parameters([Parameter(name, value=value)])
        assert not res.successful and name in res.reason and repr(value) in res.reason \
            and allowed in res.reason, (name, res.reason)
        res = node.set_parameters([Parameter(name, value=value)])[0]
        assert not res.successful and res.reason, name
    assert node.get_parameter("window_frames").value == 10 and node.p["sync_mode"] == "approximate"
    assert node.p["focal_min"] == 50.0 and node.p["noise_bound"] == 0.05
    assert node.set_parameters([Parameter("focal_min", value=100.0)])[0].successful


def test_latest_is_the_last_camera_info_and_the_estimate_behind_it(harness):
    h = harness()
    assert h.node.latest is None
    for k in range(2):
        assert h.frame(frame_messages(cam(k), T0 + k * DT))
    assert spin_until(h.ex, lambda: len(h.info) == 2 and len(h.poses) == 2, 10)
    latest, info, win = h.node.latest, h.info.msgs[-1], h.node.window_estimate
    assert latest.stamp_ns == stamp_ns(info) == T0 + DT
    assert (latest.focal, latest.cx, latest.cy) == (info.k[0], info.k[2], info.k[5])
    assert (latest.width, latest.height) == (info.width, info.height) == (640, 480)
    # Frame 2's CameraInfo went out when its depth image arrived, normally before frame 2 was
    # estimated: it carries the window of then (frame 1), which has since moved on.
    assert 1 <= latest.frames <= win.frames == 2 and 0 < latest.support <= win.support
    assert latest.std_rel is not None
    assert len(latest.objects) == len(h.poses.msgs[-1].poses) > 0  # this stamp's frame is done
    with pytest.raises(AttributeError):
        latest.focal = 1.0  # a frozen snapshot: the node cannot change it under the reader
    n = h.node.counts
    assert (n.received, n.matched, n.processed, n.camera_info_published) == (6, 2, 2, 2)
    times = h.node.processing_seconds  # one per processed frame, what the benchmark reads
    assert len(times) == 2 and all(0 < t < 60 for t in times)


def test_reset_service_clears_window_and_the_latched_estimate(harness, capfd):
    h = harness()
    for k in range(3):
        assert h.frame(frame_messages(cam(k), T0 + k * DT))
    assert len(h.node.window) == 3 and spin_until(h.ex, lambda: len(h.info) == 3, 10)
    client = h.tester.create_client(Trigger, "/fcop_node/reset")
    assert client.wait_for_service(timeout_sec=5.0)
    for _ in range(10):  # a client calling in a loop must not flood the log
        fut = client.call_async(Trigger.Request())
        assert spin_until(h.ex, fut.done, 10)
        assert fut.result().success
    assert len(h.node.window) == 0 and h.node.window.current.focal is None
    # node.latest mirrors ~/latest_camera_info (a newcomer's review: it kept the estimate).
    assert h.node.latest is None and h.node.last_estimate is None
    # A late joiner of ~/latest_camera_info gets nothing from before the reset ...
    late = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.TRANSIENT_LOCAL)
    rec = Recorder(h.tester, CameraInfo, "/fcop_node/latest_camera_info", late)
    assert spin_until(h.ex, lambda: rec.sub.get_publisher_count() == 1, 10)
    # ... and the next estimate once there is one (the frame that gives it gets its CameraInfo).
    assert h.frame(frame_messages(cam(5), T0 + 10 * DT))
    assert spin_until(h.ex, lambda: len(rec) == 1, 10)
    assert stamp_ns(rec.msgs[0]) == T0 + 10 * DT
    assert capfd.readouterr().err.count("reset by service") == 1


@pytest.mark.parametrize("restart", ["looped_bag", "reset_service"])
def test_stamps_seen_before_a_restart_get_their_camera_info_again(harness, restart):
    """A looped bag (time jumps back) or ~/reset, then the same stamps again: every depth image
    of the new lap gets its CameraInfo (until the fix, a lap after the first got none: the
    stamps were remembered as answered)."""
    h = harness()
    # 10 Hz for 1.5 s: the first five stamps of the next lap lie over 1 s back (a jump)
    lap = [T0 + k * 100_000_000 for k in range(16)]
    for k, stamp in enumerate(lap):
        assert h.frame(frame_messages(cam(k), stamp))
    assert spin_until(h.ex, lambda: len(h.info) == 16, 10)
    if restart == "reset_service":
        assert h.trigger("reset").success
    # A looped bag's jump back is held until its third frame confirms it; the first frames after
    # a restart may go before there is an estimate again (the hand-off keeps the newest).
    first = 3 if restart == "looped_bag" else 1
    for k, stamp in enumerate(lap[:first]):
        h.send(frame_messages(cam(k), stamp))
        assert spin_until(h.ex, lambda: h.node.received == 48 + 3 * (k + 1), 10)
    assert h.settle()
    for k, stamp in enumerate(lap[first:], first):
        assert h.frame(frame_messages(cam(k), stamp))
    assert spin_until(h.ex, lambda: len(h.info) >= 16 + len(lap) - first, 10), len(h.info)
    again = [stamp_ns(m) for m in h.info.msgs[16:]]
    assert again == sorted(set(again)) and again[-(len(lap) - first):] == lap[first:]


def test_a_frame_that_outlives_destroy_node_fails_quietly(harness, monkeypatch, capfd):
    """destroy_node waits a while for the frame in progress; one that takes longer then
    publishes on destroyed handles. That used to be counted and logged as a failed frame."""
    gate = Gate(monkeypatch)
    h = harness()
    gate.close()
    h.send(frame_messages(cam(0), T0))
    assert spin_until(h.ex, lambda: h.node.worker.busy_since is not None, 10)
    stop = h.node.worker.stop
    monkeypatch.setattr(h.node.worker, "stop", lambda timeout: stop(timeout=0.05))
    h.node.destroy_node()  # returns with the frame still held at the gate
    gate.open()
    h.node.worker._thread.join(10)
    assert not h.node.worker._thread.is_alive()
    assert h.node.counts.dropped["exception"] == 0
    assert "failed" not in capfd.readouterr().err


def test_a_frame_in_progress_at_ctrl_c_fails_quietly(harness, monkeypatch, capfd):
    """Ctrl-C shuts the rcl context down before the context's shutdown destroys the node and
    stops the worker: a frame in progress then fails to publish. A hostile user's trial saw it
    logged as a failed frame in 2 of 4 runs. The moment between, as the worker sees it:"""
    from fcop_ros.ros.node import RCLError
    h = harness()
    monkeypatch.setattr(h.node.context, "ok", lambda: False)
    assert not h.node.worker.stopping
    h.node._on_worker_error((T0, None), RCLError("publisher's context is invalid"))
    assert h.node.counts.dropped["exception"] == 0
    assert "failed" not in capfd.readouterr().err


def test_a_signal_while_the_node_is_built_is_a_clean_stop(monkeypatch):
    """SIGTERM or Ctrl-C during start-up (a launch file stopping the node early): rclpy's
    handler shuts the context down and rcl refuses the next publisher. That was a traceback
    and exit code 1."""
    import rclpy
    from fcop_ros.ros import node as node_module

    def interrupted_start(*args, **kwargs):
        rclpy.shutdown()
        raise node_module.RCLError("Failed to create publisher: rcl node's context is invalid")

    monkeypatch.setattr(node_module, "FcopNode", interrupted_start)
    assert node_module.main(["fcop_node"]) == 0
    assert not rclpy.ok()


def test_latched_estimate_for_late_joiners(harness):
    h = harness()
    h.send(frame_messages(clean_frame(1), T0))
    assert spin_until(h.ex, lambda: len(h.info) == 1, 20)
    late = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.TRANSIENT_LOCAL)
    rec = Recorder(h.tester, CameraInfo, "/fcop_node/latest_camera_info", late)
    assert spin_until(h.ex, lambda: len(rec) == 1, 10)
    assert rec.msgs[0].k[0] == h.info.msgs[0].k[0]


def test_diagnostics_go_on_under_sim_time_without_a_clock(harness):
    """A hostile trial: under use_sim_time with /clock silent (a bag played without it, a
    paused simulator) the node published no /diagnostics at all, so nothing could say so. The
    timer runs on the steady clock, as the rates and ages it reports do."""
    h = harness(parameter_overrides=[Parameter("use_sim_time", value=True),
                                     Parameter("diagnostics_period", value=0.1)])
    assert h.node.get_clock().now().nanoseconds == 0  # no /clock: sim time stands at zero
    rec = Recorder(h.tester, DiagnosticArray, "/diagnostics")
    assert spin_until(h.ex, lambda: len(rec) >= 3, 10)
    assert rec.msgs[-1].status[0].level == DiagnosticStatus.WARN  # no estimate yet


def test_diagnostics(harness):
    h = harness(parameter_overrides=[Parameter("diagnostics_period", value=0.1)])
    rec = Recorder(h.tester, DiagnosticArray, "/diagnostics")
    assert spin_until(h.ex, lambda: len(rec) >= 1, 10)
    st = rec.msgs[-1].status[0]
    assert st.name == "fcop_node: focal estimate" and st.level == st.WARN  # no evidence yet
    assert st.hardware_id == "/fcop_node"  # tells nodes of one name in two namespaces apart
    assert h.frame(frame_messages(clean_frame(2), T0))

    def values(msg):
        return {kv.key: kv.value for kv in msg.status[0].values}
    # Wait for the first message built after the frame was processed (one built before may
    # still be on its way), then check that one.
    assert spin_until(
        h.ex, lambda: any(values(m)["frames_processed"] == "1" for m in rec.msgs), 10
    )
    msg = next(m for m in rec.msgs if values(m)["frames_processed"] == "1")
    st, v = msg.status[0], values(msg)
    assert st.level == st.OK, st.message
    assert abs(float(v["focal_px"]) / clean_frame(2).focal - 1) < 1e-3
    assert 0 <= float(v["std_rel"]) <= h.node.p["max_uncertainty"]
    for key in ("window_fill", "frame_rate_hz", "estimator_rate_hz", "estimate_age_s",
                "sync_dropped", "processing_ms_median", "frames_skipped", "camera_info_published"):
        assert key in v, key
    assert v["estimator_kernels"] == compiled.describe() and v["estimator_kernels"]


def test_the_kernels_lines_stay_off_rosout(harness):
    """The warm-up's lines come from the worker thread, whose rosout publish can race a
    Ctrl-C's shutdown (rcl printed "Failed to publish log message to rosout" once in CI): they
    go to the console only, and the node's own lines still reach /rosout."""
    from rcl_interfaces.msg import Log

    h = harness()  # waits for the warm-up: its lines are logged by now
    qos = QoSProfile(depth=1000, durability=DurabilityPolicy.TRANSIENT_LOCAL,
                     reliability=ReliabilityPolicy.RELIABLE)
    logs = Recorder(h.tester, Log, "/rosout", qos)
    h.node.get_logger().info("marker after the warm-up")
    assert spin_until(h.ex, lambda: any(m.msg == "marker after the warm-up" for m in logs.msgs),
                      10)
    ours = [m.msg for m in logs.msgs if m.name.startswith("fcop_node")]
    assert any("fcop_node ready" in m for m in ours), ours
    assert not any("kernels" in m for m in ours), ours


def test_kernels_that_fail_to_build_leave_the_numpy_estimator(harness, monkeypatch):
    """A compiler failure at start-up is logged and the node estimates with numpy instead."""
    def broken():
        raise RuntimeError("no LLVM here")

    monkeypatch.setattr(compiled, "ENABLED", True)
    monkeypatch.setattr(compiled, "warm_up", broken)
    h = harness()
    fr = clean_frame(2)
    assert h.frame(frame_messages(fr, T0))
    assert not compiled.ENABLED and not h.node._warming_up
    assert spin_until(h.ex, lambda: len(h.info) == 1, 10)
    assert abs(h.info.msgs[0].k[0] / fr.focal - 1) < 1e-3


def test_mixed_encodings_work(harness):
    h = harness()
    fr = clean_frame(3)
    h.send(frame_messages(fr, T0, depth_encoding="16UC1", nocs_encoding="rgb8",
                          mask_encoding="16UC1"))
    assert spin_until(h.ex, lambda: len(h.info) == 1, 20)
    # 1 mm depth and 1/255 NOCS quantisation: still within 2%.
    assert abs(h.info.msgs[0].k[0] / fr.focal - 1) < 0.02


@pytest.mark.parametrize("case", sorted(BAD_CASES))
def test_bad_content_never_publishes(harness, case):
    h = harness()
    h.send(frame_messages(corrupted(clean_frame(0), case), T0))
    assert h.settle(1)
    assert (
        h.node.counts.camera_info_published == 0
        and len(h.info) == 0
        and h.node.counts.dropped["no_evidence"] == 1
    )


def test_wrong_encoding_and_size_mismatch(harness):
    h = harness()
    fr = clean_frame(0)
    d, n, m = frame_messages(fr, T0)
    wrong = Image(header=d.header, height=d.height, width=d.width, encoding="rgb8",
                  step=d.width * 3, data=bytes(d.width * d.height * 3))
    h.send((wrong, n, m))
    # one frame at a time: the worker takes only the newest of frames that wait for it
    assert h.settle(1)
    small = frame_messages(clean_frame(0, 320, 240), T0 + DT)
    h.send((small[0], n, m), which=(0,))
    h.send((d, n, m), which=(1, 2))
    n2 = frame_messages(fr, T0 + DT)
    h.send((small[0], n2[1], n2[2]))
    assert h.settle(2)
    dropped = h.node.counts.dropped
    assert dropped["bad_encoding"] == 1 and dropped["size_mismatch"] == 1
    assert h.node.counts.camera_info_published == 0 and len(h.info) == 0
    # The node is alive and still estimates.
    h.send(frame_messages(fr, T0 + 2 * DT))
    assert spin_until(h.ex, lambda: len(h.info) == 1, 20)


def test_stamps_backwards_and_silent_topic(harness, capfd):
    h = harness()
    fr = clean_frame(0)
    assert h.frame(frame_messages(fr, T0 + 10 * DT))
    h.send(frame_messages(fr, T0 + 5 * DT))  # slightly back: late, dropped
    assert spin_until(h.ex, lambda: h.node.counts.dropped["sync_late"] == 3, 10)
    assert h.node.sync.stats.matched == 1
    # One input silent: nothing is matched, the other queues stay bounded (drop oldest). Its
    # silence shows once no frame has matched for 5 s (before, drops are how a slower input
    # meets a faster one): the node's clock is moved on past that.
    later = time.monotonic() + 6.0
    h.node._now = lambda: later
    seen = lambda: h.node.sync.pending() + h.node.counts.dropped["sync_queue_full"]  # noqa: E731
    for k in range(12):
        h.send(frame_messages(fr, T0 + (20 + k) * DT), which=(0, 1))
        # one frame at a time: no DDS-side loss
        assert spin_until(h.ex, lambda: seen() == 2 * (k + 1), 10)
    assert h.node.counts.dropped["sync_queue_full"] == 14
    # the log names the inputs dropped and the silent one they waited for
    err = capfd.readouterr().err
    assert "in the synchroniser: queue full (depth 1)" in err
    assert "nothing from mask for 6 s (stopped?)" in err, err
    assert h.node.sync.stats.matched == 1 and h.node.sync.pending() <= 2 * h.node.p["queue_size"]
    # A sustained jump back (a looped bag: three frames) resets the synchroniser and the window,
    # and uses the frames it held while waiting for the confirmation.
    for k in range(3):
        h.send(frame_messages(fr, T0 - (100 - k) * DT))
        assert spin_until(h.ex, lambda: h.node.received == 3 + 3 + 24 + 3 * (k + 1), 10)
    assert h.settle()
    assert h.node.sync.stats.resets == 1 and h.node.sync.stats.matched == 4
    # the depth and NOCS waiting for a mask
    assert h.node.counts.dropped["sync_time_jump_reset"] == 10
    assert (
        h.node.counts.dropped.total()
        == h.node.counts.dropped["sync_late"]
        + h.node.counts.dropped["sync_queue_full"]
        + h.node.counts.dropped["estimator_busy"]
        + 10
    )
    assert (
        h.node.window.current.focal is not None
        and len(h.node.window) + h.node.counts.skipped == 3
    )
    # The held frames come out at once and replace each other in the hand-off: not a slow
    # estimator, which every lap of a looped bag used to log (a hostile trial).
    err = capfd.readouterr().err
    assert "the estimator is slower than the input" not in err
    assert h.node.counts.skipped == 0 or "3 frames matched at once" in err, err


@pytest.mark.parametrize("bad", [0, T0 + 3600 * 10**9])  # stamped 0; an hour ahead
def test_isolated_outlier_stamp_keeps_the_window(harness, capfd, bad):
    h = harness()
    for k in range(3):
        assert h.frame(frame_messages(cam(k), T0 + k * DT))
    h.send(frame_messages(cam(3), bad))
    assert spin_until(h.ex, lambda: h.node.sync.held() == 3, 10)
    assert h.frame(frame_messages(cam(4), T0 + 4 * DT))
    assert len(h.node.window) == 4 and h.node.sync.stats.resets == 0
    assert {k: v for k, v in h.node.counts.dropped.items() if v} == {
        "outlier_stamp_depth": 1, "outlier_stamp_nocs": 1, "outlier_stamp_mask": 1}
    assert spin_until(h.ex, lambda: len(h.info) == 4, 10), (
        [stamp_ns(m) - T0 for m in h.info.msgs],
        h.node.counts.camera_info_published,
        h.node.counts.dropped,
    )
    assert bad not in [stamp_ns(m) for m in h.info.msgs]  # no CameraInfo with the bogus stamp
    err = capfd.readouterr().err
    assert (
        "mask message(s) with an outlier stamp" in err
        and "depth message(s) with an outlier stamp" in err
    )


def test_only_the_mask_stamped_zero_is_named_and_never_resets(harness, capfd):
    h = harness()
    assert h.frame(frame_messages(cam(0), T0))
    for k in range(1, 6):
        d, n, m = frame_messages(cam(0), T0 + k * DT)
        m.header.stamp.sec = m.header.stamp.nanosec = 0
        h.send((d, n, m))
        assert spin_until(h.ex, lambda: h.node.received == 3 * (k + 1), 10)
    assert h.node.sync.stats.resets == 0 and len(h.node.window) == 1
    assert h.node.counts.dropped["outlier_stamp_mask"] == 4  # the fifth is still held
    assert "mask message(s) with an outlier stamp" in capfd.readouterr().err


def test_mirrored_nocs_are_warned_not_counted_as_rejected(harness, capfd):
    """A NOCS image whose channels are reversed (bgr as rgb) fits only as a mirror image: the
    frame is used (the focal does not care), so it is a warning, not a rejection."""
    from dataclasses import replace

    h = harness()
    fr = clean_frame(4)
    fr = replace(fr, nocs=np.ascontiguousarray(fr.nocs[..., ::-1]))
    assert h.frame(frame_messages(fr, T0))
    assert h.node.counts.warnings["mirrored_nocs"] >= 1
    assert h.node.counts.dropped.total() == 0 and len(h.node.window) == 1
    assert abs(h.node.window_estimate.focal / fr.focal - 1) < 1e-2
    assert "only as a mirror image" in capfd.readouterr().err


def test_mismatched_and_empty_frame_ids_are_warned(harness, capfd):
    h = harness()
    d, n, m = frame_messages(clean_frame(4), T0)
    n.header = header_from_ns(T0, "nocs_frame")
    assert h.frame((d, n, m))
    d, n, m = frame_messages(clean_frame(4), T0 + DT)
    m.header = header_from_ns(T0 + DT, "")
    assert h.frame((d, n, m))
    assert h.node.counts.warnings == {"frame_id_mismatch": 1, "frame_id_empty": 1}
    d, n, m = frame_messages(clean_frame(4), T0 + 2 * DT)  # both at once: each is counted
    n.header, m.header = header_from_ns(T0 + 2 * DT, "nocs_frame"), header_from_ns(T0 + 2 * DT, "")
    assert h.frame((d, n, m))
    assert h.node.counts.warnings == {"frame_id_mismatch": 2, "frame_id_empty": 2}
    err = capfd.readouterr().err
    assert "nocs 'nocs_frame'" in err and "mask ''" in err
    assert h.node.counts.dropped.total() == 0 and len(h.node.window) == 3  # warned, still used


def test_header_is_copied_from_depth(harness):
    h = harness()
    d, n, m = frame_messages(clean_frame(4), T0)
    d.header.frame_id = "my_depth_frame"
    h.send((d, n, m))
    assert spin_until(h.ex, lambda: len(h.info) == 1, 20)
    assert h.info.msgs[0].header.frame_id == "my_depth_frame" and stamp_ns(h.info.msgs[0]) == T0


def test_every_depth_image_gets_one_camera_info_while_the_estimator_is_stuck(harness, monkeypatch):
    gate = Gate(monkeypatch)
    # A deep synchroniser queue must not turn into an estimator backlog (issue 9.7).
    h = harness(parameter_overrides=[Parameter("queue_size", value=50)])
    try:
        assert h.frame(frame_messages(cam(0), T0))
        gate.close()
        h.send(frame_messages(cam(1), T0 + DT))
        # The estimator holds frame 1.
        assert spin_until(h.ex, lambda: h.node.worker.busy_since is not None, 10)
        for k in range(2, 10):
            h.send(frame_messages(cam(k), T0 + k * DT))
            # Published while the estimator cannot finish anything: publishing does not wait
            # for it.
            assert spin_until(h.ex, lambda: len(h.info) == k + 1, 10)
        # frames 2..8 replaced by newer ones
        assert h.node.processed == 1 and h.node.counts.skipped == 7
    finally:
        gate.open()
    assert h.settle()
    assert spin_until(h.ex, lambda: len(h.poses) == 3, 10)
    # each exactly once
    assert [stamp_ns(m) for m in h.info.msgs] == [T0 + k * DT for k in range(10)]
    assert all(abs(m.k[0] / 600.0 - 1) < 1e-3 for m in h.info.msgs)
    # The estimator went from frame 1 straight to the newest, frame 9: no backlog.
    assert [stamp_ns(m) for m in h.poses.msgs] == [T0, T0 + DT, T0 + 9 * DT]
    assert h.node.counts.dropped["estimator_busy"] == 7


def test_diagnostics_error_when_the_estimator_stalls_and_warn_when_behind(
    harness, monkeypatch, capfd
):
    gate = Gate(monkeypatch)
    h = harness(parameter_overrides=[Parameter("diagnostics_period", value=0.1),
                                     Parameter("max_estimate_age", value=0.3)])
    rec = Recorder(h.tester, DiagnosticArray, "/diagnostics")
    # The rates look back 5 s; on a loaded machine (CI beside another job) the skips below
    # slid out of that span before the last check. The rule, not the wall clock, is tested.
    h.node._rates.seconds = 120.0
    try:
        assert h.frame(frame_messages(cam(0), T0))
        # A rates reading before the skips: the rates count from the oldest reading within
        # their span (the node's start counts only until the second reading), and where the
        # sends below outran the first 0.1 s timer, the first reading came after all eight
        # skips and the status read OK (in CI, the runs of 2255fb8 and deccd64).
        assert spin_until(h.ex, lambda: len(rec) > 0, 10)
        gate.close()
        for k in range(1, 11):
            h.send(frame_messages(cam(k), T0 + k * DT))
            assert spin_until(h.ex, lambda: h.node.received == 3 * (k + 1), 10)

        # The first message built after all ten frames were in (one built earlier has fewer drops).
        def after_all(m):
            return {kv.key: kv.value for kv in m.status[0].values}.get(
                "dropped_estimator_busy"
            ) == "8"

        assert spin_until(h.ex, lambda: rec.msgs and after_all(rec.msgs[-1])
                          and rec.msgs[-1].status[0].level == DiagnosticStatus.ERROR, 10)
        st = rec.msgs[-1].status[0]
        v = {kv.key: kv.value for kv in st.values}
        # 2 decimals
        assert "estimator stalled" in st.message and float(v["estimator_busy_s"]) >= 0.3
        # the drops are logged
        assert "the estimator is slower than the input" in capfd.readouterr().err
    finally:
        gate.open()
    assert h.settle()
    n = len(rec)
    # Once it runs again: behind (skipped 8 frames, estimated 3 in the last 5 s), no longer
    # stalled. Only this node's messages count (its own drop count).
    assert spin_until(
        h.ex, lambda: len(rec) > n and after_all(rec.msgs[-1])
        and rec.msgs[-1].status[0].level != DiagnosticStatus.ERROR, 10
    )
    st = rec.msgs[-1].status[0]
    assert st.level == DiagnosticStatus.WARN and "behind" in st.message, (
        st.level, st.message, {kv.key: kv.value for kv in st.values})


def test_image_size_change_starts_a_new_window(harness, capfd):
    h = harness()
    assert h.frame(frame_messages(cam(0), T0))
    assert h.frame(frame_messages(cam(1), T0 + DT))
    small = clean_frame(2, 320, 240, 300.0)  # another camera mode: half the size, half the focal
    assert h.frame(frame_messages(small, T0 + 2 * DT))
    assert len(h.node.window) == 1 and abs(h.node.window.current.focal / 300.0 - 1) < 1e-3
    assert "image size changed from 640x480 to 320x240" in capfd.readouterr().err
    # Its depth image arrived while the estimate was for 640x480 (none then); it gets its own
    # CameraInfo once the new window has an estimate.
    assert spin_until(h.ex, lambda: len(h.info) == 3, 10)
    last = h.info.msgs[-1]
    assert stamp_ns(last) == T0 + 2 * DT and (last.width, last.height) == (320, 240)
    assert abs(last.k[0] / 300.0 - 1) < 1e-3 and last.k[2] == 159.5


def test_a_stray_frame_of_another_size_without_evidence_keeps_the_window(harness, capfd):
    """A frame of another size that gives no focal is a counted drop: the window and the
    CameraInfo of the following frames of the window's size stay as they were."""
    from msg_adapters import depth_to_image, mask_to_image, nocs_to_image
    h = harness()
    for k in range(3):
        assert h.frame(frame_messages(clean_frame(k, 320, 240, 300.0), T0 + k * DT))
    assert spin_until(h.ex, lambda: len(h.info) == 3, 10)
    hdr = header_from_ns(T0 + 3 * DT, "camera_optical_frame")
    stray = (depth_to_image(np.full((16, 16), np.nan, np.float32), "32FC1", hdr),
             nocs_to_image(np.zeros((16, 16, 3), np.float32), "32FC3", hdr),
             mask_to_image(np.zeros((16, 16), np.uint8), "mono8", hdr))
    assert h.frame(stray)
    assert h.node.counts.dropped["other_size_no_evidence"] == 1 and len(h.node.window) == 3
    assert abs(h.node.window.current.focal / 300.0 - 1) < 1e-3
    assert h.node.diagnostic_status().level == DiagnosticStatus.OK
    for k in range(4, 6):
        assert h.frame(frame_messages(clean_frame(k, 320, 240, 300.0), T0 + k * DT))
    assert spin_until(h.ex, lambda: len(h.info) == 5, 10)
    assert [stamp_ns(m) for m in h.info.msgs[3:]] == [T0 + 4 * DT, T0 + 5 * DT]
    assert all((m.width, m.height) == (320, 240) and abs(m.k[0] / 300.0 - 1) < 1e-3
               for m in h.info.msgs)
    assert len(h.node.window) == 5
    err = capfd.readouterr().err
    assert "image size changed" not in err and "16x16 frame without focal evidence" in err


def test_a_frame_stamped_before_1970_gets_its_camera_info(harness):
    """builtin_interfaces/Time allows a negative sec; a hostile user's frame at sec=-5 was
    estimated and posed but got no CameraInfo (the stamp compared with a start value of -1)."""
    h = harness()
    assert h.frame(frame_messages(clean_frame(1), -5_000_000_000))
    assert spin_until(h.ex, lambda: len(h.info) == 1, 10)
    assert stamp_ns(h.info.msgs[0]) == -5_000_000_000


def test_frames_refused_for_their_encoding_warn_and_name_the_newest(harness):
    """A hostile user's trial: NOCS sent as 32FC1 after a good start gave 41 of 41 frames
    rejected while /diagnostics stayed OK and CameraInfo came from the old window; the newest
    frame's reason shown was an earlier frame's, and stayed after ~/reset."""
    h = harness()
    h.node._rates.seconds = 120.0  # all nine frames within the rates' span, however slow
    for k in range(3):
        assert h.frame(frame_messages(clean_frame(1), T0 + k * DT))
    st = h.node.diagnostic_status()
    assert st.level == DiagnosticStatus.OK, st.message
    for k in range(3, 9):
        d, n, m = frame_messages(clean_frame(1), T0 + k * DT)
        flat = Image(header=n.header, height=n.height, width=n.width, encoding="32FC1",
                     step=n.width * 4, data=bytes(n.width * n.height * 4))
        assert h.frame((d, flat, m))
    assert h.node.counts.dropped["bad_encoding"] == 6
    st = h.node.diagnostic_status()
    assert st.level == DiagnosticStatus.WARN, st.message
    assert "6 of the " in st.message and "(the newest: dropped: " in st.message
    assert "32FC1" in st.message
    h.node._on_reset(Trigger.Request(), Trigger.Response())
    assert "newest" not in h.node.diagnostic_status().message


def test_frames_that_fail_count_as_frames_without_a_focal(harness, monkeypatch, capfd):
    """A newcomer's review: a frame whose estimate raised was counted as an exception but not
    as a frame without a focal, so /diagnostics stayed OK on a node whose every frame failed."""
    h = harness()
    h.node._rates.seconds = 120.0
    for k in range(3):
        assert h.frame(frame_messages(clean_frame(1), T0 + k * DT))

    def broken(*args, **kwargs):
        raise RuntimeError("boom")
    monkeypatch.setattr("fcop_ros.ros.node.estimate_frame", broken)
    for k in range(3, 9):
        assert h.frame(frame_messages(clean_frame(1), T0 + k * DT))
    assert h.node.counts.dropped["exception"] == 6
    st = h.node.diagnostic_status()
    assert st.level == DiagnosticStatus.WARN, st.message
    assert "6 of the 9 frames" in st.message, st.message
    assert "(the newest: failed: RuntimeError: boom)" in st.message, st.message
    err = capfd.readouterr().err
    assert "RuntimeError: boom" in err
    assert err.count("the first failed frame's traceback") == 1 and "in broken" in err


def test_frames_that_fail_from_the_start_are_not_called_no_frames(harness, monkeypatch):
    """A hostile trial: with every frame failing from the start, /diagnostics said 'no
    focal estimate yet: no frames yet' while frames_processed counted up."""
    def broken(*args, **kwargs):
        raise RuntimeError("boom")
    monkeypatch.setattr("fcop_ros.ros.node.estimate_frame", broken)
    h = harness()
    for k in range(3):
        assert h.frame(frame_messages(clean_frame(1), T0 + k * DT))
    st = h.node.diagnostic_status()
    assert ("no focal estimate yet: none of the 3 frames estimated reached the window; the "
            "newest frame: failed: RuntimeError: boom") in st.message, st.message
    # The count starts again with the window: after ~/reset, the frames since it (the window
    # used to be judged by its reason's words, and said 'window reset' however many failed).
    h.node._on_reset(Trigger.Request(), Trigger.Response())
    for k in range(3, 5):
        assert h.frame(frame_messages(clean_frame(1), T0 + k * DT))
    st = h.node.diagnostic_status()
    assert ("no focal estimate yet: none of the 2 frames estimated reached the window; the "
            "newest frame: failed: RuntimeError: boom") in st.message, st.message


def test_after_a_reset_a_frame_of_another_size_is_no_stray(harness, capfd):
    """A hostile user's trial: after ~/reset a 16x16 frame without evidence was dropped as a
    stray 'the window keeps its 640x480 frames', of a window with no frames."""
    from msg_adapters import depth_to_image, mask_to_image, nocs_to_image
    h = harness()
    assert h.frame(frame_messages(clean_frame(1), T0))
    h.node._on_reset(Trigger.Request(), Trigger.Response())
    hdr = header_from_ns(T0 + DT, "camera_optical_frame")
    tiny = (depth_to_image(np.full((16, 16), np.nan, np.float32), "32FC1", hdr),
            nocs_to_image(np.zeros((16, 16, 3), np.float32), "32FC3", hdr),
            mask_to_image(np.zeros((16, 16), np.uint8), "mono8", hdr))
    assert h.frame(tiny)
    assert h.node.counts.dropped["other_size_no_evidence"] == 0
    assert h.node.counts.dropped["no_evidence"] == 1
    assert "keeps its 640x480" not in capfd.readouterr().err


def test_depth_without_nocs_ages_the_estimate_and_diagnostics_say_so(harness):
    """A reviewer stopped the NOCS topic: CameraInfo went on with the old estimate and
    /diagnostics stayed OK. Depth images answered while no complete frame matches now WARN."""
    h = harness()
    assert h.frame(frame_messages(clean_frame(1), T0))
    assert h.node.diagnostic_status().level == DiagnosticStatus.OK
    for k in range(1, 4):
        h.send(frame_messages(clean_frame(1), T0 + k * DT), which=(0,))  # depth only
    assert spin_until(h.ex, lambda: h.node.counts.camera_info_published == 4, 10)
    st = h.node.diagnostic_status()
    assert st.level == DiagnosticStatus.WARN, st.message
    assert "3 depth images" in st.message and "no matched depth, NOCS and mask set" in st.message
    # Five seconds on (the node's clock moved), with depth still coming: the message names the
    # inputs that went silent.
    later = time.monotonic() + 6.0
    h.node._now = lambda: later
    h.send(frame_messages(clean_frame(1), T0 + 4 * DT), which=(0,))
    assert spin_until(h.ex, lambda: h.node.counts.camera_info_published == 5, 10)
    st = h.node.diagnostic_status()
    assert "no nocs message for 6." in st.message and "no mask message for 6." in st.message
    values = {kv.key: float(kv.value) for kv in st.values if kv.key.endswith("_age_s")}
    assert values["depth_age_s"] == 0.0 and values["nocs_age_s"] > 6.0, values


def test_every_input_silent_warns_that_the_focal_is_an_old_one(harness):
    """A hostile trial stopped the camera: /diagnostics said OK, 'focal 601.1 px', for 20 s."""
    h = harness()
    assert h.frame(frame_messages(clean_frame(1), T0))
    assert h.node.diagnostic_status().level == DiagnosticStatus.OK
    later = time.monotonic() + 6.0
    h.node._now = lambda: later
    st = h.node.diagnostic_status()
    assert st.level == DiagnosticStatus.WARN and "no input for 6." in st.message, st.message


def test_a_change_of_health_is_said_in_the_log_once(harness, capfd):
    """Left alone before: with every input stopped /diagnostics went WARN but the console
    said nothing. A change of level is logged when it begins and when it ends; the start's
    'no focal estimate yet' is not."""
    h = harness()
    h.node.publish_diagnostics()  # no frames yet: WARN, not news
    assert h.frame(frame_messages(clean_frame(1), T0))
    h.node.publish_diagnostics()
    assert h.node.diagnostic_status().level == DiagnosticStatus.OK
    later = time.monotonic() + 6.0
    h.node._now = lambda: later
    for _ in range(3):
        h.node.publish_diagnostics()
    h.node._now = time.monotonic
    assert h.frame(frame_messages(clean_frame(1), T0 + DT))
    h.node.publish_diagnostics()
    err = capfd.readouterr().err
    assert "no focal estimate yet" not in err
    assert err.count("no input for 6.") == 1, err
    assert err.count("healthy again: focal ") == 1, err


def test_a_problem_under_the_start_up_warning_is_said_too(harness, capfd):
    """A hostile trial: frames without evidence (empty masks), then the camera stopped. The
    status stayed WARN 'no focal estimate yet' throughout, so neither /diagnostics nor the log
    said the input had stopped."""
    from dataclasses import replace

    h = harness()
    empty = replace(clean_frame(1), mask=np.zeros_like(clean_frame(1).mask))
    for k in range(3):
        assert h.frame(frame_messages(empty, T0 + k * DT))
    h.node.publish_diagnostics()
    later = time.monotonic() + 8.0
    h.node._now = lambda: later
    st = h.node.publish_diagnostics().status[0]
    assert st.level == DiagnosticStatus.WARN and "no input for 8." in st.message, st.message
    h.node.publish_diagnostics()
    err = capfd.readouterr().err
    assert err.count("no input for 8.") == 1, err


def test_an_unreadable_depth_image_gets_no_camera_info_once_there_is_an_estimate(harness, capfd):
    """A new user's audit (25 Nov 2026): once a 640x480 estimate existed, a depth Image of that
    size with no encoding and no data, an rgb8 one, one with data short of step * height got a
    CameraInfo each (only the size was checked). A depth image the node cannot read gets none,
    counted as warning_depth_unreadable and said."""
    h = harness()
    assert h.frame(frame_messages(clean_frame(1), T0))
    assert spin_until(h.ex, lambda: len(h.info) == 1, 10)
    d, n, m = frame_messages(clean_frame(1), T0 + DT)
    bad = [Image(header=header_from_ns(T0 + DT, d.header.frame_id), width=640, height=480),
           Image(header=header_from_ns(T0 + 2 * DT, d.header.frame_id), width=640, height=480,
                 encoding="rgb8", step=1920, data=bytes(640 * 480 * 3)),
           Image(header=header_from_ns(T0 + 3 * DT, d.header.frame_id), width=640, height=480,
                 encoding="32FC1", step=2560, data=bytes(100))]
    for img in bad:
        h.send((img, n, m), which=(0,))
    # A readable depth image after them is answered: they had their turn.
    h.send(frame_messages(clean_frame(1), T0 + 4 * DT), which=(0,))
    assert spin_until(h.ex, lambda: len(h.info) == 2, 10)
    assert [stamp_ns(i) for i in h.info.msgs] == [T0, T0 + 4 * DT]
    assert h.node.counts.warnings["depth_unreadable"] == 3
    err = capfd.readouterr().err
    assert "no CameraInfo for an unreadable depth: unsupported encoding ''" in err


def test_the_latched_camera_info_is_withdrawn_when_the_gate_closes_on_it(harness):
    """A new user's audit (25 Nov 2026): after focal_max was lowered below the estimate at run
    time, /diagnostics said the focal was held back, but a late joiner of ~/latest_camera_info
    still got it. The latched publication goes when the gate closes on it, and comes back with
    the next CameraInfo the gate lets out."""
    h = harness()
    assert h.frame(frame_messages(clean_frame(1), T0))
    assert spin_until(h.ex, lambda: len(h.info) == 1, 10)
    late = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.TRANSIENT_LOCAL)
    first = Recorder(h.tester, CameraInfo, "/fcop_node/latest_camera_info", late)
    assert spin_until(h.ex, lambda: len(first) == 1, 10)
    focal = first.msgs[0].k[0]
    assert h.node.set_parameters([Parameter("focal_max", value=focal - 50.0)])[0].successful
    assert spin_until(h.ex, lambda: h.node.latest is None, 10)
    again = Recorder(h.tester, CameraInfo, "/fcop_node/latest_camera_info", late)
    assert spin_until(h.ex, lambda: again.sub.get_publisher_count() == 1, 10)
    assert not spin_until(h.ex, lambda: len(again) > 0, 1.0)  # nothing latched
    assert h.node.set_parameters([Parameter("focal_max", value=focal + 50.0)])[0].successful
    assert h.frame(frame_messages(clean_frame(1), T0 + DT))
    assert spin_until(h.ex, lambda: len(again) == 1, 10)
    assert stamp_ns(again.msgs[0]) == T0 + DT


def test_a_frame_of_another_frame_id_starts_a_new_window(harness):
    """The node passes the depth image's frame_id to the tracker (test_tracker has the rule):
    three frames in one camera frame, then one in another, leave a window of one, counted."""
    h = harness()
    for k in range(3):
        assert h.frame(frame_messages(clean_frame(1), T0 + k * DT))
    assert len(h.node.window) == 3
    msgs = frame_messages(clean_frame(1), T0 + 3 * DT)
    for m in msgs:
        m.header.frame_id = "other_camera_optical_frame"
    assert h.frame(msgs)
    assert len(h.node.window) == 1
    assert h.node.counts.warnings["frame_id_changed"] == 1
