"""ROS 2 messages <-> numpy for fcop_ros (no cv_bridge, no rclpy: message packages only)."""
from .image import (DEPTH_ENCODINGS, MASK_ENCODINGS, NOCS_ENCODINGS, ImageFormatError,
                    array_to_image, depth_from_image, depth_to_image, image_to_array,
                    mask_from_image, mask_to_image, nocs_from_image, nocs_to_image)
from .outputs import camera_info, marker_array, object_poses, pose_array, stamp_ns

__all__ = ["DEPTH_ENCODINGS", "MASK_ENCODINGS", "NOCS_ENCODINGS", "ImageFormatError",
           "array_to_image", "depth_from_image", "depth_to_image", "image_to_array",
           "mask_from_image", "mask_to_image", "nocs_from_image", "nocs_to_image", "camera_info",
           "marker_array", "object_poses", "pose_array", "stamp_ns"]
