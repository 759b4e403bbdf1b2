"""fcop_node parameters: bad values at start-up (the installed executable, as a user runs it),
and every parameter that can be set at run time changes what the node does (or is read-only)."""
import os
import subprocess
import sys

import numpy as np
import pytest
import yaml
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from rclpy.parameter import Parameter
from std_srvs.srv import Trigger

from fcop_ros.ros.params import PARAMETERS, READ_ONLY
from fcop_ros.synthetic.scenes import camera_frame as cam, clean_frame, noisy_frame
from msg_adapters import header_from_ns
from ros_helpers import (FRAME_ID, Gate, Recorder, frame_messages, rotation_errors, spin_until,
                         stamp_ns)

BIN = os.path.dirname(sys.executable)
T0 = 1_700_000_000_000_000_000
DT = 33_333_333


def values(status):
    return {kv.key: kv.value for kv in status.values}


# ----- start-up: one line, the parameter, its value and what is allowed; exit 2; no traceback

@pytest.mark.parametrize("arg, expected", [
    ("focal_min:=30000.0", ["focal_min=30000.0", "below focal_max=20000.0"]),
    ("window_frames:=0", ["window_frames=0", "[1, 1000]"]),
    ("min_frames:=40", ["min_frames=40", "at most window_frames=30"]),
    ("window_frames:=abc", ["window_frames='abc'", "an integer in [1, 1000]"]),
    ("sync_mode:=fuzzy", ["sync_mode='fuzzy'", "one of exact, approximate"]),
    ("principal_point_x:=-5.0", ["principal_point_x=-5.0", "[-1.0, 1000000.0]"]),
    # QoS overrides: rclpy declares them when the node creates its topics.
    ("qos_overrides./depth.subscription.depth:=abc",
     ["qos_overrides./depth.subscription.depth='abc'", "an integer"]),
    ("qos_overrides./depth.subscription.reliability:=sometimes",
     ["qos_overrides./depth.subscription.reliability='sometimes'", "reliable, best_effort"]),
    ("qos_overrides./camera_info.publisher.history:=7",
     ["qos_overrides./camera_info.publisher.history=7", "keep_last"]),
    # rclpy's InvalidServiceNameException was a traceback (a newcomer's review, stop 27).
    ("set_camera_info_service:=set info",
     ["set_camera_info_service='set info'", "a service name (topic name must not contain"]),
    # rclpy's own parameter of the wrong type raised InvalidParameterTypeException, a traceback
    # (a hostile user's trial, stop 38).
    ("use_sim_time:=maybe", ["use_sim_time", "to 'maybe' of type 'STRING', expecting type "
                                             "'BOOL'"]),
])
def test_bad_parameter_at_start_up_is_one_line_and_exit_2(arg, expected):
    exe = os.path.join(BIN, "fcop_node")
    res = subprocess.run([exe, "--ros-args", "-p", arg], capture_output=True,
                         text=True, timeout=60)
    lines = [ln for ln in res.stderr.splitlines() if ln.strip()]
    assert res.returncode == 2, res.stderr
    assert "Traceback" not in res.stderr and len(lines) == 1, res.stderr
    assert all(e in lines[0] for e in expected), lines[0]


@pytest.mark.parametrize("arg, expected", [
    # rcl leaves these unset: rclpy raised ParameterUninitializedException, a traceback.
    ("focal_max:=[]", "parameter focal_max has no value: a number in"),
    ("camera_name:=#x", "parameter camera_name has no value: a string"),
    # rcl refuses these in rclpy.init: its RCLError was re-raised, a traceback.
    ("camera_name:=", "Couldn't parse parameter override rule: '-p camera_name:='"),
    ("focal_max:=[1, a]", "Sequence should be of same type"),
])
def test_value_rcl_cannot_take_at_start_up_ends_in_a_line_and_exit_2(arg, expected):
    """A hostile user's trial: values rcl leaves unset or refuses ended in tracebacks (exit 1).
    rcl logs a line of its own before refusing; the node's line is the last."""
    exe = os.path.join(BIN, "fcop_node")
    res = subprocess.run([exe, "--ros-args", "-p", arg], capture_output=True,
                         text=True, timeout=60)
    lines = [ln for ln in res.stderr.splitlines() if ln.strip()]
    assert res.returncode == 2 and "Traceback" not in res.stderr, res.stderr
    assert lines[-1].startswith("fcop_node: ") and expected in lines[-1], res.stderr


def test_multi_document_params_file_passes_the_node_check(tmp_path):
    """rcl reads every document of a params file, a later value winning; the node's own
    check refused such a file as not YAML."""
    path = tmp_path / "two.yaml"
    path.write_text("/**:\n  ros__parameters:\n    window_frames: 5\n---\n"
                    "/**:\n  ros__parameters:\n    window_frames: 7\n")
    from fcop_ros.ros.command_line import params_file_problem
    assert params_file_problem(["fcop_node", "--ros-args", "--params-file", str(path)]) == ""


def test_unreadable_params_file_at_start_up_is_one_line_and_exit_2(tmp_path):
    exe = os.path.join(BIN, "fcop_node")
    missing = str(tmp_path / "nonexistent.yaml")
    res = subprocess.run([exe, "--ros-args", "--params-file", missing], capture_output=True,
                         text=True, timeout=60)
    lines = [ln for ln in res.stderr.splitlines() if ln.strip()]
    assert res.returncode == 2, res.stderr
    assert "Traceback" not in res.stderr and len(lines) == 1, res.stderr
    assert missing in lines[0] and "params file" in lines[0], lines[0]


@pytest.mark.parametrize("text", ["- just\n- a list\n", "fcop_node:\n  focal_min: 300.0\n"])
def test_params_file_that_names_no_parameters_is_one_line_and_exit_2(tmp_path, text):
    """YAML that is no params file (a list; a node without ``ros__parameters``): rcl logged a
    line of its own before the node's."""
    exe = os.path.join(BIN, "fcop_node")
    path = tmp_path / "params.yaml"
    path.write_text(text)
    res = subprocess.run([exe, "--ros-args", "--params-file", str(path)], capture_output=True,
                         text=True, timeout=60)
    lines = [ln for ln in res.stderr.splitlines() if ln.strip()]
    assert res.returncode == 2, res.stderr
    assert "Traceback" not in res.stderr and len(lines) == 1, res.stderr
    assert "names no parameters" in lines[0] and "ros__parameters" in lines[0], lines[0]


def test_help_prints_usage_and_does_not_start_the_node():
    exe = os.path.join(BIN, "fcop_node")
    res = subprocess.run([exe, "--help"], capture_output=True, text=True, timeout=60)
    assert res.returncode == 0, res.stderr
    assert res.stdout.startswith("usage: fcop_node") and "exit codes" in res.stdout
    assert "ready" not in res.stdout + res.stderr


@pytest.mark.parametrize("overrides, expected", [
    ({"focal_min": 30000.0},
     "parameter focal_min=30000.0 is not allowed: it must be below focal_max=20000.0"),
    ({"noise_bound": 0.9}, "parameter noise_bound=0.9 is not allowed: a fraction in (0, 0.5]"),
    # Both given (as a params file gives them all): the one moved from its default is blamed.
    ({"focal_min": 50.0, "focal_max": 10.0},
     "parameter focal_max=10.0 is not allowed: it must be above focal_min=50.0"),
    ({"camera_name": "my camera"}, "parameter camera_name='my camera' is not allowed"),
    ({"set_camera_info_service": "{bad}"},
     "parameter set_camera_info_service='{bad}' is not allowed: a service name (topic name "
     "'{bad}' is invalid: unknown substitution: {bad})"),  # a traceback before (a trial)
    ({"set_camera_info_service": "cam//set_camera_info"},
     "parameter set_camera_info_service='cam//set_camera_info' is not allowed: a service name "
     "(topic name must not contain repeated '/')"),
])
def test_bad_parameter_in_process_raises_parameter_error(overrides, expected):
    from fcop_ros.ros.node import FcopNode
    from fcop_ros.ros.params import ParameterError
    from ros_helpers import ros_context
    with ros_context() as (ctx, ex):
        with pytest.raises(ParameterError) as err:
            FcopNode(
                context=ctx,
                parameter_overrides=[Parameter(k, value=v) for k, v in overrides.items()],
            )
        assert str(err.value).startswith(expected)


def test_valid_qos_overrides_are_applied(harness):
    h = harness(node_args=["--ros-args", "-p", "qos_overrides./camera_info.publisher.depth:=3",
                           "-p", "qos_overrides./camera_info.publisher.history:=KEEP_LAST",
                           "-p", "qos_overrides./nocs.subscription.depth:=2"])
    assert h.node.pub_info.qos_profile.depth == 3 and h.node._subs[1].qos_profile.depth == 2


def test_a_qos_override_changes_its_own_topic_only(harness):
    """rclpy writes an override into the profile it is handed: a shared profile carried one
    topic's override to every topic created after it (a hostile user's trial: a reliable
    /mask made camera_info_in reliable too, a best-effort camera_info the poses and markers),
    and into rclpy's own qos_profile_sensor_data for every later node of the process."""
    from rclpy.qos import ReliabilityPolicy, qos_profile_sensor_data
    h = harness(node_args=[
        "--ros-args", "-p", "qos_overrides./depth.subscription.depth:=2",
        "-p", "qos_overrides./camera_info.publisher.reliability:=best_effort"])
    assert [s.qos_profile.depth for s in h.node._subs] == [2, 5, 5]
    assert h.node.sub_info_in.qos_profile.depth == 5
    assert h.node.pub_info.qos_profile.reliability == ReliabilityPolicy.BEST_EFFORT
    assert h.node.pub_poses.qos_profile.reliability == ReliabilityPolicy.RELIABLE
    assert h.node.pub_markers.qos_profile.reliability == ReliabilityPolicy.RELIABLE
    assert qos_profile_sensor_data.depth == 5


def test_bad_qos_override_in_process_raises_parameter_error():
    from fcop_ros.ros.node import FcopNode
    from fcop_ros.ros.params import ParameterError
    from ros_helpers import ros_context
    args = ["--ros-args", "-p", "qos_overrides./mask.subscription.history:=forever"]
    with ros_context() as (ctx, ex):
        with pytest.raises(ParameterError) as err:
            FcopNode(context=ctx, cli_args=args)
        assert str(err.value).startswith(
            "parameter qos_overrides./mask.subscription.history='forever' is not allowed: one of"
        )

def test_a_parameter_the_node_does_not_have_is_named(harness, capfd):
    """rclpy ignores an override of an undeclared parameter without a word; the node names it
    and the likely intended one, and runs with its defaults."""
    h = harness(node_args=["--ros-args", "-p", "window_frame:=5", "-p", "max_uncertanty:=0.2",
                           "-p", "qos_overrides./nope.subscription.depth:=3",
                           # a policy rclpy takes no override of (a warning, not a refusal)
                           "-p", "qos_overrides./depth.subscription.durability:=transient_local"])
    assert h.node.p["window_frames"] == 30
    err = capfd.readouterr().err
    assert "parameter window_frame is not one of this node's; ignored (did you mean " \
        "window_frames?)" in err
    assert "parameter max_uncertanty is not one of this node's; ignored (did you mean " \
        "max_uncertainty?)" in err
    assert "parameter qos_overrides./nope.subscription.depth is not one of this node's; " \
        "ignored (the topics that take QoS overrides: /camera_info_in, /depth, /mask, /nocs, " \
        "/camera_info, /object_poses, /object_markers)" in err
    assert "parameter qos_overrides./depth.subscription.durability is not one of this " \
        "node's; ignored (QoS overrides take history, depth, reliability here)" in err
    assert err.count("is not one of this node's") == 4
    h = harness(node_args=["--ros-args", "-p", "use_sim_time:=false", "-p",
                           "qos_overrides./depth.subscription.depth:=3", "-p", "seed:=4"])
    assert "is not one of this node's" not in capfd.readouterr().err


def test_setting_a_parameter_the_node_does_not_have_names_the_likely_one(harness, capfd):
    """At run time rclpy refuses it with 'Invalid access to undeclared parameter(s): []', naming
    none (a new user's trial, by the parameter service as `ros2 param set` calls it); the node
    names it and the likely intended one in its log."""
    from rcl_interfaces.srv import SetParameters
    h = harness()
    client = h.tester.create_client(SetParameters, "/fcop_node/set_parameters")
    assert client.wait_for_service(timeout_sec=5.0)
    request = SetParameters.Request(
        parameters=[Parameter("window_frame", value=10).to_parameter_msg()])
    future = client.call_async(request)
    assert spin_until(h.ex, future.done, 10)
    assert not future.result().results[0].successful
    assert h.node.p["window_frames"] == 30
    assert ("cannot set parameter window_frame: not one of this node's (did you mean "
            "window_frames?)") in capfd.readouterr().err


def test_integer_for_a_float_parameter_is_taken(harness):
    # `-p focal_min:=300` is what people type; rclpy alone refuses an INTEGER for a DOUBLE.
    h = harness(node_args=["--ros-args", "-p", "focal_min:=300"])
    assert h.node.p["focal_min"] == 300.0
    # At run time too (`ros2 param set /fcop_node focal_min 250` sends an INTEGER).
    set_ok(h, focal_min=250)
    assert h.node.get_parameter("focal_min").value == 250.0 and h.node.p["focal_min"] == 250.0
    assert isinstance(h.node.p["focal_min"], float)


def test_parameters_in_conflict_are_refused_naming_the_one_set(harness):
    h = harness()
    for values_, reason in [
        ({"focal_max": 10.0},
         "parameter focal_max=10.0 is not allowed: it must be above focal_min=50.0"),
        ({"focal_min": 30000.0},
         "parameter focal_min=30000.0 is not allowed: it must be below focal_max=20000.0"),
        # a window that can never hold min_frames frames would never publish
        ({"min_frames": 31},
         "parameter min_frames=31 is not allowed: it must be at most window_frames=30"),
        ({"window_frames": 4, "min_frames": 5},
         "parameter min_frames=5 is not allowed: it must be at most window_frames=4"),
    ]:
        res = h.node.set_parameters_atomically(
            [Parameter(k, value=v) for k, v in values_.items()])
        assert not res.successful and res.reason == reason, res.reason
    set_ok(h, min_frames=5)
    res = h.node.set_parameters([Parameter("window_frames", value=4)])[0]
    assert res.reason == ("parameter window_frames=4 is not allowed: it must be at least "
                          "min_frames=5")
    set_ok(h, window_frames=5)


# ----- run time: each settable parameter changes behaviour

def frames_then(h, n=3, first=0, frame=cam):
    for k in range(first, first + n):
        assert h.frame(frame_messages(frame(k), T0 + k * DT))


def set_ok(h, **values_):
    res = h.node.set_parameters([Parameter(k, value=v) for k, v in values_.items()])
    assert all(r.successful for r in res), [r.reason for r in res]


def check_window_frames(h):
    frames_then(h, 3)
    set_ok(h, window_frames=2)
    assert len(h.node.window) == 2 and h.node.window.current.focal is not None  # evidence kept
    set_ok(h, window_frames=30)  # grown again: the frame the smaller window left comes back
    assert len(h.node.window) == 3


def check_window_seconds(h):
    frames_then(h, 3)  # 33 ms apart
    set_ok(h, window_seconds=0.05)
    assert len(h.node.window) == 2 and h.node.window.current.focal is not None
    set_ok(h, window_seconds=0.0)
    assert len(h.node.window) == 3


def check_min_frames(h):
    frames_then(h, 3)
    set_ok(h, min_frames=5)
    assert h.node.window.current.focal is None and len(h.node.window) == 3
    set_ok(h, min_frames=2)  # back, without a new frame: the evidence was kept
    assert h.node.window.current.focal is not None


def check_min_window_votes(h):
    frames_then(h, 2)
    set_ok(h, min_window_votes=10_000_000)
    assert h.node.window.current.focal is None and len(h.node.window) == 2
    set_ok(h, min_window_votes=30)
    assert h.node.window.current.focal is not None


def _inliers(h, k, frame):
    assert h.frame(frame_messages(frame(k), T0 + k * DT))
    return h.node.last_estimate.inlier_count


def check_triplets_per_object(h):
    before = _inliers(h, 0, cam)
    set_ok(h, triplets_per_object=10)
    after = _inliers(h, 1, cam)
    assert before > 50 >= after  # at most 10 votes per object, 5 objects


def moderate(k):
    return noisy_frame(k, "moderate")


def check_noise_bound(h):
    before = _inliers(h, 0, moderate)
    set_ok(h, noise_bound=0.0005)
    assert _inliers(h, 0 + 1, lambda k: moderate(0)) < 0.5 * before


def check_noise_bound_mode(h):
    before = _inliers(h, 0, moderate)
    set_ok(h, noise_bound_mode="absolute")  # 0.05 px instead of 5% of f
    assert _inliers(h, 1, lambda k: moderate(0)) < 0.5 * before


def check_focal_min(h):
    frames_then(h, 1)
    assert abs(h.node.last_estimate.focal / 600 - 1) < 0.01
    set_ok(h, focal_min=700.0)
    frames_then(h, 1, first=1)
    f = h.node.last_estimate.focal
    assert f is None or f >= 700.0


def check_focal_max(h):
    frames_then(h, 1)
    set_ok(h, focal_max=500.0)
    frames_then(h, 1, first=1)
    f = h.node.last_estimate.focal
    assert f is None or f <= 500.0


@pytest.mark.parametrize("change", [dict(focal_min=400.0, focal_max=2000.0),
                                    dict(focal_max=250.0)])
def test_focal_range_set_at_run_time_bounds_every_published_focal(harness, change):
    """focal_range bounds every published focal: the window's focal of before a run-time change
    that puts it outside the new range is held back at once, and diagnostics say why."""
    h = harness(parameter_overrides=[Parameter("diagnostics_period", value=60.0)])

    def small(k):
        return clean_frame(k, 320, 240, 300.0)
    frames_then(h, 3, frame=small)
    assert abs(h.node.window.current.focal / 300.0 - 1) < 1e-3 and h.node.latest is not None
    published = h.node.counts.camera_info_published
    set_ok(h, **change)
    st = h.node.diagnostic_status()
    assert st.level == DiagnosticStatus.WARN and "outside focal_range" in st.message, st.message
    frames_then(h, 2, first=3, frame=small)  # each depth image is answered in its callback
    assert h.node.counts.camera_info_published == published
    assert abs(h.node.window.current.focal / 300.0 - 1) < 1e-3  # still in the window, held back
    st = h.node.diagnostic_status()
    assert st.level == DiagnosticStatus.WARN and "outside focal_range" in st.message, st.message
    res = h.node._on_save_calibration(Trigger.Request(), Trigger.Response())
    assert not res.success and "outside focal_range" in res.message, res.message
    set_ok(h, focal_min=50.0, focal_max=20000.0)  # back: the window's focal is published again
    frames_then(h, 1, first=5, frame=small)
    assert h.node.counts.camera_info_published == published + 1
    assert h.node.diagnostic_status().level == DiagnosticStatus.OK

def check_min_object_pixels(h):
    frames_then(h, 1)
    set_ok(h, min_object_pixels=10_000_000)
    frames_then(h, 1, first=1)
    assert h.node.last_estimate.focal is None and h.node.counts.dropped["no_evidence"] == 1


def check_depth_scale(h):
    fr = cam(0)

    def z_of_first_pose(k):
        h.send(frame_messages(fr, T0 + k * DT, depth_encoding="16UC1"))
        assert spin_until(h.ex, lambda: len(h.poses) == k + 1, 20)
        return h.poses.msgs[-1].poses[0].position.z
    z1 = z_of_first_pose(0)
    set_ok(h, depth_scale=0.002)
    z2 = z_of_first_pose(1)
    assert abs(z2 / z1 - 2) < 0.01


def check_principal_point_x(h):
    frames_then(h, 1)
    set_ok(h, principal_point_x=300.0)
    frames_then(h, 1, first=1)
    assert spin_until(h.ex, lambda: len(h.info) == 2, 10) and h.info.msgs[-1].k[2] == 300.0


def check_principal_point_y(h):
    frames_then(h, 1)
    set_ok(h, principal_point_y=200.0)
    frames_then(h, 1, first=1)
    assert spin_until(h.ex, lambda: len(h.info) == 2, 10) and h.info.msgs[-1].k[5] == 200.0


def check_principal_point_std(h):
    frames_then(h, 1)
    assumed = h.node.last_estimate
    set_ok(h, principal_point_std=0.0)
    frames_then(h, 1, first=1)
    assert assumed.std_rel_principal_point > 0 and assumed.principal_point_offset is not None
    assert h.node.last_estimate.std_rel_principal_point == 0.0
    assert h.node.last_estimate.principal_point_offset is None


def check_lens_distortion_std(h):
    frames_then(h, 1)
    with_term = h.node.last_estimate
    set_ok(h, lens_distortion_std=0.0)
    frames_then(h, 1, first=1)
    assert with_term.std_rel_lens > 0 and h.node.last_estimate.std_rel_lens == 0.0
    assert with_term.lens_k1 is not None and h.node.last_estimate.lens_k1 is None


def _skewed(h, k, skew_ns):
    d, n, m = frame_messages(cam(0), T0 + k * DT)
    n.header = header_from_ns(T0 + k * DT + skew_ns, FRAME_ID)
    m.header = header_from_ns(T0 + k * DT + skew_ns, FRAME_ID)
    h.send((d, n, m))
    assert spin_until(h.ex, lambda: h.node.received == 3 * (k + 1), 10)


def check_sync_mode(h):
    _skewed(h, 0, 5_000_000)
    assert h.node.sync.stats.matched == 0
    set_ok(h, sync_mode="approximate")  # sync_slop 0.01
    # Frame 1 waits for the next depth image (its rate not yet known, a nearer one might come).
    _skewed(h, 1, 5_000_000)
    _skewed(h, 2, 5_000_000)
    assert h.node.sync.stats.matched == 2


def check_sync_slop(h):
    set_ok(h, sync_mode="approximate", sync_slop=0.001)
    _skewed(h, 0, 5_000_000)
    assert h.node.sync.stats.matched == 0
    set_ok(h, sync_slop=0.01)
    _skewed(h, 1, 5_000_000)
    _skewed(h, 2, 5_000_000)
    assert h.node.sync.stats.matched == 2


def check_queue_size(h):
    msgs = [frame_messages(cam(0), T0 + k * DT) for k in range(8)]
    for k, trio in enumerate(msgs):
        h.send(trio, which=(0,))
        assert spin_until(h.ex, lambda: h.node.received == k + 1, 10)
    assert h.node.sync.pending() == 5
    set_ok(h, queue_size=2)
    assert h.node.sync.pending() == 2


def check_publish_poses(h):
    frames_then(h, 1)
    assert spin_until(h.ex, lambda: len(h.poses) == 1 and len(h.markers) == 1, 10)
    set_ok(h, publish_poses=False)
    frames_then(h, 1, first=1)
    assert spin_until(h.ex, lambda: len(h.markers) == 2, 10)
    assert h.node.counts.frames_published == 2 and len(h.poses) == 1


def check_publish_markers(h):
    frames_then(h, 1)
    assert spin_until(h.ex, lambda: len(h.poses) == 1 and len(h.markers) == 1, 10)
    set_ok(h, publish_markers=False)
    frames_then(h, 1, first=1)
    assert spin_until(h.ex, lambda: len(h.poses) == 2, 10)
    assert h.node.counts.frames_published == 2 and len(h.markers) == 1


def check_max_uncertainty(h):
    # Frame 1 of the moderate preset: std_rel 1.1%, inside the default bound (frame 0's 5.9% is
    # held back from the start).
    frames_then(h, 1, frame=lambda k: moderate(1))
    assert spin_until(h.ex, lambda: len(h.info) == 1, 10)
    std = h.node.window.current.std_rel
    set_ok(h, max_uncertainty=max(std / 10, 1e-6))  # held back now
    frames_then(h, 1, first=1, frame=lambda k: moderate(1))
    assert h.node.counts.camera_info_published == 1
    assert h.node.diagnostic_status().level == DiagnosticStatus.WARN
    set_ok(h, max_uncertainty=0.05)  # published again, for the next depth image
    frames_then(h, 1, first=2, frame=lambda k: moderate(1))
    assert spin_until(h.ex, lambda: len(h.info) == 2, 10)
    assert stamp_ns(h.info.msgs[-1]) == T0 + 2 * DT


def check_diagnostics_period(h):
    rec = Recorder(h.tester, DiagnosticArray, "/diagnostics")
    assert spin_until(h.ex, lambda: rec.sub.get_publisher_count() >= 1, 10)
    set_ok(h, diagnostics_period=0.1)  # from 60 s (harness start-up value)
    assert spin_until(h.ex, lambda: len(rec) >= 3, 10)
    assert h.node._diag_timer.timer_period_ns == 100_000_000


def check_max_estimate_age(h, monkeypatch):
    gate = Gate(monkeypatch)
    clock = [1000.0]
    h.node._now = lambda: clock[0]
    frames_then(h, 1)
    gate.close()
    try:
        h.send(frame_messages(cam(1), T0 + DT))
        assert spin_until(h.ex, lambda: h.node.worker.busy_since is not None, 10)
        clock[0] += 1.0  # busy for one second (default max_estimate_age 2 s)
        assert h.node.diagnostic_status().level == DiagnosticStatus.OK
        set_ok(h, max_estimate_age=0.5)
        st = h.node.diagnostic_status()
        assert st.level == DiagnosticStatus.ERROR and "stalled" in st.message
    finally:
        gate.open()


def check_nocs_convention(h):
    set_ok(h, max_uncertainty=1.0)  # the wrong reading has a large std_rel: publish it anyway
    fr = cam(0)
    h.send(frame_messages(fr, T0))
    assert spin_until(h.ex, lambda: len(h.poses) == 1 and len(h.markers) == 1, 20)
    # a new window: the two readings disagree
    h.node._on_reset(Trigger.Request(), Trigger.Response())
    # the same (fcop-convention) input read the other way
    set_ok(h, nocs_convention="nocs_dataset")
    h.send(frame_messages(fr, T0 + DT))
    assert spin_until(h.ex, lambda: len(h.poses) == 2 and len(h.markers) == 2, 20)
    assert np.median(rotation_errors(h.poses.msgs[0], h.markers.msgs[0], fr)) < 1.0
    assert np.median(rotation_errors(h.poses.msgs[1], h.markers.msgs[1], fr)) > 20.0


def check_camera_name(h, tmp_path):
    set_ok(h, calibration_file=str(tmp_path / "c.yaml"))
    frames_then(h, 1)
    set_ok(h, camera_name="left_cam")
    assert h.trigger("save_calibration").success
    assert yaml.safe_load((tmp_path / "c.yaml").read_text())["camera_name"] == "left_cam"


def check_calibration_file(h, tmp_path):
    frames_then(h, 1)
    set_ok(h, calibration_file=str(tmp_path / "a.yaml"))
    assert h.trigger("save_calibration").success and (tmp_path / "a.yaml").is_file()
    set_ok(h, calibration_file=str(tmp_path / "sub" / "b.yaml"))
    assert h.trigger("save_calibration").success and (tmp_path / "sub" / "b.yaml").is_file()


BEHAVIOUR = {
    name: globals()["check_" + name] for name in PARAMETERS if "check_" + name in globals()
}


def test_every_parameter_is_tested_at_run_time_or_read_only():
    untested = set(PARAMETERS) - set(BEHAVIOUR) - READ_ONLY
    assert not untested, f"write check_<name> for {sorted(untested)}"
    assert not set(BEHAVIOUR) & READ_ONLY


@pytest.mark.parametrize("name", sorted(BEHAVIOUR))
def test_parameter_set_at_run_time_changes_behaviour(harness, monkeypatch, tmp_path, name):
    h = harness(parameter_overrides=[Parameter("diagnostics_period", value=60.0),
                                     Parameter("calibration_file",
                                               value=str(tmp_path / "cal.yaml"))])
    fn = BEHAVIOUR[name]
    kwargs = {k: v for k, v in (("monkeypatch", monkeypatch), ("tmp_path", tmp_path))
              if k in fn.__code__.co_varnames[:fn.__code__.co_argcount]}
    fn(h, **kwargs)


@pytest.mark.parametrize("name", sorted(READ_ONLY))
def test_read_only_parameters_are_refused_at_run_time(harness, name):
    h = harness()
    d = h.node.describe_parameter(name)
    assert d.read_only
    value = {"seed": 5, "set_camera_info_service": "/x/set_camera_info"}[name]
    res = h.node.set_parameters([Parameter(name, value=value)])[0]  # the descriptor: rclpy refuses
    assert not res.successful and "read-only" in res.reason and name in res.reason
    assert h.node.p[name] == PARAMETERS[name].default


# ----- principal point, rates

def test_principal_point_outside_the_image_is_refused(harness):
    h = harness(parameter_overrides=[Parameter("principal_point_x", value=700.0)])
    h.send(frame_messages(cam(0), T0))
    assert h.settle(1)
    counts = h.node.counts
    assert counts.dropped["principal_point_outside"] == 1 and counts.camera_info_published == 0
    set_ok(h, principal_point_x=320.0)
    assert h.frame(frame_messages(cam(0), T0 + DT))
    assert spin_until(h.ex, lambda: len(h.info) == 1, 10) and h.info.msgs[0].k[2] == 320.0
    # Now the image size is known: a value outside it is refused at once, with the range.
    res = h.node.set_parameters([Parameter("principal_point_y", value=480.0)])[0]
    assert (
        not res.successful and "principal_point_y=480.0" in res.reason and "[0, 479]" in res.reason
    )
    assert h.node.p["principal_point_y"] == -1.0


def test_frame_rate_reads_above_40_hz(harness):
    h = harness()
    clock = [500.0]
    h.node._now = lambda: clock[0]
    h.node.publish_diagnostics()  # the first sample
    tiny = clean_frame(0, 32, 24)
    for k in range(500):  # 500 frames in 5 s: 100 Hz
        msgs = frame_messages(tiny, T0 + k * 10_000_000)
        for i in range(3):
            h.node._on_image(i, msgs[i])
    clock[0] += 5.0
    v = values(h.node.publish_diagnostics().status[0])
    assert float(v["frame_rate_hz"]) == pytest.approx(100.0)
