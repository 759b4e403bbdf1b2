"""Builders for the node's outputs: CameraInfo (REP-104), PoseArray and MarkerArray."""
from __future__ import annotations

import copy

import numpy as np
from geometry_msgs.msg import Pose, PoseArray
from scipy.spatial.transform import Rotation
from sensor_msgs.msg import CameraInfo
from visualization_msgs.msg import Marker, MarkerArray


def camera_info(focal: float, cx: float, cy: float, width: int, height: int, header=None) -> CameraInfo:
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


def _pose(rotation: np.ndarray, translation: np.ndarray) -> Pose:
    p = Pose()
    p.position.x, p.position.y, p.position.z = (float(v) for v in translation)
    x, y, z, w = Rotation.from_matrix(np.asarray(rotation)).as_quat()
    p.orientation.x, p.orientation.y, p.orientation.z, p.orientation.w = float(x), float(y), float(z), float(w)
    return p


def pose_array(objects, header=None) -> PoseArray:
    """One pose per object (fcop_ros pose convention: the NOCS box centre, in the optical frame)."""
    msg = PoseArray()
    if header is not None:
        msg.header = copy.deepcopy(header)
    msg.poses = [_pose(o.rotation, o.translation) for o in objects]
    return msg


def marker_array(objects, header=None, ns: str = "fcop_objects") -> MarkerArray:
    """A DELETEALL marker (clears the previous frame's boxes) then one CUBE per object.

    Each cube is the object's pose with edge scale / sqrt(3): the cube whose diagonal is the
    object's bounding-box diagonal (one NOCS unit = ``scale`` metres)."""
    out = MarkerArray()
    clear = Marker()
    if header is not None:
        clear.header = copy.deepcopy(header)
    clear.ns = ns
    clear.action = Marker.DELETEALL
    out.markers.append(clear)
    for o in objects:
        m = Marker()
        if header is not None:
            m.header = copy.deepcopy(header)
        m.ns = ns
        m.id = int(o.instance_id)
        m.type = Marker.CUBE
        m.action = Marker.ADD
        m.pose = _pose(o.rotation, o.translation)
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
