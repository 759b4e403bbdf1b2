"""Builders for the node's outputs: CameraInfo (REP-104), PoseArray and MarkerArray."""
from __future__ import annotations

import copy

import numpy as np
from geometry_msgs.msg import Pose, PoseArray
from scipy.spatial.transform import Rotation
from sensor_msgs.msg import CameraInfo
from visualization_msgs.msg import Marker, MarkerArray


def camera_info(focal: float, cx: float, cy: float, width: int, height: int,
                header=None) -> CameraInfo:
    """REP-104 CameraInfo of a pinhole camera with fx = fy = focal and no distortion.

    K = [f 0 cx; 0 f cy; 0 0 1], R = I, P = [K | 0], ``plumb_bob`` with five zero D, binning 0
    (= 1) and an all-zero ROI (= the full frame). ``header`` (the depth image's) is copied.
    """
    msg = CameraInfo()
    if header is not None:
        msg.header = copy.deepcopy(header)
    msg.width, msg.height = int(width), int(height)
    msg.distortion_model = "plumb_bob"
    msg.d = [0.0] * 5
    f, cx, cy = float(focal), float(cx), float(cy)
    msg.k = [f, 0.0, cx, 0.0, f, cy, 0.0, 0.0, 1.0]
    msg.r = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]
    msg.p = [f, 0.0, cx, 0.0, 0.0, f, cy, 0.0, 0.0, 0.0, 1.0, 0.0]
    msg.binning_x = msg.binning_y = 0
    return msg


def object_poses(objects) -> list[Pose]:
    """geometry_msgs/Pose of each object; the quaternions in one batched conversion."""
    if not objects:
        return []
    quats = Rotation.from_matrix(np.stack([np.asarray(o.rotation) for o in objects])).as_quat()
    out = []
    for o, (x, y, z, w) in zip(objects, quats):
        p = Pose()
        p.position.x, p.position.y, p.position.z = (float(v) for v in o.translation)
        q = p.orientation
        q.x, q.y, q.z, q.w = float(x), float(y), float(z), float(w)
        out.append(p)
    return out


def pose_array(objects, header=None, poses=None) -> PoseArray:
    """One pose per object (fcop_ros pose convention: the NOCS box centre, in the optical frame).
    ``poses``: the objects' Pose messages if already built (see :func:`marker_array`)."""
    msg = PoseArray()
    if header is not None:
        msg.header = copy.deepcopy(header)
    msg.poses = list(poses) if poses is not None else object_poses(objects)
    return msg


def marker_array(objects, header=None, ns: str = "fcop_objects", poses=None) -> MarkerArray:
    """A DELETEALL marker (clears the previous frame's boxes) then one CUBE per object.

    Each cube is the object's pose with edge scale / sqrt(3): the cube whose diagonal is the
    object's bounding-box diagonal (one NOCS unit = ``scale`` metres). ``poses`` as in
    :func:`pose_array`."""
    out = MarkerArray()
    clear = Marker()
    if header is not None:
        clear.header = copy.deepcopy(header)
    clear.ns = ns
    clear.action = Marker.DELETEALL
    out.markers.append(clear)
    for o, pose in zip(objects, poses if poses is not None else object_poses(objects)):
        m = Marker()
        if header is not None:
            m.header = copy.deepcopy(header)
        m.ns = ns
        m.id = int(o.instance_id)
        m.type = Marker.CUBE
        m.action = Marker.ADD
        m.pose = pose
        edge = float(o.scale) / np.sqrt(3.0)
        m.scale.x = m.scale.y = m.scale.z = edge
        hue = (int(o.instance_id) * 0.61803) % 1.0
        m.color.r, m.color.g, m.color.b = (float(c) for c in _hsv(hue))
        m.color.a = 0.5
        out.markers.append(m)
    return out


def _hsv(h: float):
    """A saturated colour for hue h in [0,1), distinct per instance."""
    i = int(h * 6) % 6
    f = h * 6 - int(h * 6)
    return [(1, f, 0), (1 - f, 1, 0), (0, 1, f), (0, 1 - f, 1), (f, 0, 1), (1, 0, 1 - f)][i]
