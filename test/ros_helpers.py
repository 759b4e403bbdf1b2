"""In-process ROS 2 test harness: a private Context and executor per test, spin with a deadline."""
from __future__ import annotations

import signal
import threading
import time

import numpy as np
import pytest
from geometry_msgs.msg import PoseArray
from rclpy.node import Node
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import CameraInfo, Image
from std_srvs.srv import Trigger
from visualization_msgs.msg import MarkerArray

from fcop_ros.ros.spin import ros_context, spin_until  # noqa: F401 (re-exported for the tests)
from msg_adapters import (  # noqa: F401 (stamp_ns re-exported for the tests)
    depth_to_image, header_from_ns, mask_to_image, nocs_to_image, stamp_ns)

FRAME_ID = "camera_optical_frame"


def call_service(executor, client, request, timeout: float = 60.0, resend_after: float = 5.0):
    """Call an idempotent service across processes and return its response, or None after
    ``timeout`` s. A request is sent again when no response came in ``resend_after`` s: with
    Fast DDS a server may answer before its response writer has matched the client's reader
    (ros2/rmw_fastrtps#392), and that response is lost, though ``service_is_ready`` held."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        fut = client.call_async(request)
        if spin_until(executor, fut.done, min(resend_after, deadline - time.monotonic())):
            return fut.result()
        client.remove_pending_request(fut)
    return None


def frame_messages(frame, stamp: int, depth_encoding="32FC1", nocs_encoding="32FC3",
                   mask_encoding="mono8"):
    """Depth, NOCS and mask Image messages of a rendered frame stamped ``stamp`` (ns), all with the
    same header."""
    h = header_from_ns(stamp, FRAME_ID)
    return (depth_to_image(frame.depth, depth_encoding, h),
            nocs_to_image(frame.nocs, nocs_encoding, h),
            mask_to_image(frame.mask, mask_encoding, h))


class Recorder:
    """Collects the messages of one topic."""

    def __init__(self, node, msg_type, topic, qos=10):
        self.msgs = []
        self.sub = node.create_subscription(msg_type, topic, self.msgs.append, qos)

    def __len__(self):
        return len(self.msgs)


def as_array(values) -> np.ndarray:
    return np.asarray(values, dtype=np.float64)


class Harness:
    """fcop_node plus a tester node that publishes inputs and records outputs."""

    def __init__(self, ctx, executor, node_args=None, inputs=("depth", "nocs", "mask"),
                 **node_kwargs):
        from fcop_ros.ros.node import FcopNode
        self.node = FcopNode(context=ctx, cli_args=node_args, **node_kwargs)
        self.tester = Node("tester", context=ctx)
        self.pubs = [self.tester.create_publisher(Image, t, qos_profile_sensor_data)
                     for t in inputs]
        self.info = Recorder(self.tester, CameraInfo, "camera_info")
        self.poses = Recorder(self.tester, PoseArray, "object_poses")
        self.markers = Recorder(self.tester, MarkerArray, "object_markers")
        self.ex = executor
        executor.add_node(self.node)
        executor.add_node(self.tester)
        assert spin_until(executor, lambda: all(p.get_subscription_count() for p in self.pubs), 10)
        # Frames sent while the kernels load would race the warm-up: the worker skips all but
        # the newest (a first run on a machine compiles them, up to a minute).
        assert spin_until(executor, lambda: not self.node.warming_up, 180)

    def trigger(self, service: str):
        """Call the node's std_srvs/Trigger service ``~/<service>`` and return its response."""
        client = self.tester.create_client(Trigger, f"/fcop_node/{service}")
        assert client.wait_for_service(timeout_sec=5.0)
        fut = client.call_async(Trigger.Request())
        assert spin_until(self.ex, fut.done, 10)
        self.tester.destroy_client(client)
        return fut.result()

    def send(self, msgs, which=(0, 1, 2)):
        for i in which:
            self.pubs[i].publish(msgs[i])

    def settle(self, processed=None, timeout=20.0):
        """Spin until the estimator has taken (or skipped) every matched frame and is idle."""
        node = self.node
        if processed is None:
            return spin_until(self.ex, lambda: node.received and node.idle() and (
                node.processed + node.counts.skipped >= node.sync.stats.matched), timeout)
        return spin_until(self.ex, lambda: node.processed >= processed and node.idle(), timeout)

    def frame(self, msgs):
        """Send one frame and spin until the estimator has processed it."""
        target = self.node.processed + 1
        self.send(msgs)
        return self.settle(target)

    def close(self):
        self.node.destroy_node()
        self.tester.destroy_node()


@pytest.fixture
def harness():
    """harness(args=None, **Harness kwargs): a fcop_node and a tester in a private context."""
    made = []

    def make(args=None, **kw):
        ctx_mgr = ros_context(args)
        ctx, ex = ctx_mgr.__enter__()
        try:
            h = Harness(ctx, ex, **kw)
        except BaseException:
            ctx_mgr.__exit__(None, None, None)
            raise
        made.append((h, ctx_mgr))
        return h

    yield make
    for h, ctx_mgr in made:
        h.close()
        ctx_mgr.__exit__(None, None, None)


def rotation_errors(poses_msg, markers_msg, frame) -> list:
    """Rotation error in degrees of each published object pose against the frame's truth (the
    markers carry the instance ids, in the order of the poses)."""
    from scipy.spatial.transform import Rotation

    from fcop_ros.core.pose import rotation_angle_deg
    truth = {o.instance_id: o for o in frame.objects}
    out = []
    for pose, marker in zip(poses_msg.poses, markers_msg.markers[1:]):
        q = pose.orientation
        R = Rotation.from_quat([q.x, q.y, q.z, q.w]).as_matrix()
        out.append(rotation_angle_deg(R, truth[marker.id].rotation))
    return out


class Gate:
    """Holds the node's estimator: once closed, every frame estimate waits until it is opened."""

    def __init__(self, monkeypatch):
        import fcop_ros.ros.frame_estimate as frame_module
        self.event = threading.Event()
        self.event.set()
        real = frame_module.estimate_focal

        def gated(*args, **kwargs):
            self.event.wait(60)
            return real(*args, **kwargs)
        monkeypatch.setattr(frame_module, "estimate_focal", gated)

    def close(self):
        self.event.clear()

    def open(self):
        self.event.set()


def as_at_a_terminal() -> None:
    """``preexec_fn`` of a child the test sends Ctrl-C to: SIGINT at its default, as a shell at
    a terminal starts a command. A test run started in the background (``pytest ... &`` from a
    script) ignores SIGINT and its children inherit that, so a tool rightly ignores the Ctrl-C
    these tests send (three Ctrl-C tests failed so, exit 0 after a whole run)."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)
