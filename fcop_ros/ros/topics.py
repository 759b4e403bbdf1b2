"""The node's topics as users remap them (relative names) and their message types, written once
for the node and the tools that feed it or read it. No rclpy."""
from __future__ import annotations

from geometry_msgs.msg import PoseArray
from sensor_msgs.msg import CameraInfo
from visualization_msgs.msg import MarkerArray

#: The image inputs (sensor_msgs/Image), in the order the synchroniser and every frame keep.
INPUTS = ("depth", "nocs", "mask")
#: The driver's CameraInfo: its P's principal point and baseline, its size (D, R: a warning).
CAMERA_INFO_IN = "camera_info_in"
#: The outputs, topic -> message type.
OUTPUTS = {"camera_info": CameraInfo, "object_poses": PoseArray, "object_markers": MarkerArray}


def type_name(cls) -> str:
    """A message class's ROS type name, e.g. 'geometry_msgs/msg/PoseArray' (as bags store it)."""
    return f"{cls.__module__.split('.')[0]}/msg/{cls.__name__}"
