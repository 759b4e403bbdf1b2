"""ROS 2 messages <-> numpy for fcop_ros (no cv_bridge, no rclpy: message packages only).

input_images: Image <-> numpy for depth, NOCS and masks, and stamps <-> nanoseconds;
output_messages: the builders of the node's CameraInfo, PoseArray and MarkerArray."""
from .input_images import (
    DEPTH_ENCODINGS,
    MASK_ENCODINGS,
    NOCS_ENCODINGS,
    ImageFormatError,
    ImageSizeMismatch,
    array_to_image,
    check_image,
    depth_from_image,
    depth_to_image,
    frame_from_images,
    header_from_ns,
    image_to_array,
    mask_from_image,
    mask_to_image,
    nocs_from_image,
    nocs_to_image,
    stamp_ns,
    time_from_ns,
    time_to_ns,
    to_fcop_convention,
)
from .output_messages import camera_info, marker_array, object_poses, pose_array

__all__ = [
    "DEPTH_ENCODINGS",
    "MASK_ENCODINGS",
    "NOCS_ENCODINGS",
    "ImageFormatError",
    "ImageSizeMismatch",
    "array_to_image",
    "camera_info",
    "check_image",
    "depth_from_image",
    "depth_to_image",
    "frame_from_images",
    "header_from_ns",
    "image_to_array",
    "marker_array",
    "mask_from_image",
    "mask_to_image",
    "nocs_from_image",
    "nocs_to_image",
    "object_poses",
    "pose_array",
    "stamp_ns",
    "time_from_ns",
    "time_to_ns",
    "to_fcop_convention",
]
