"""fcop_ros: camera focal length from category-level object priors (fCOP), as a library and a
ROS 2 node. Importing this package does not import rclpy."""
from .core import (PAPER_FCOP_IS, EstimatorOptions, FocalEstimate, FocalWindow, NoiseBound,
                   ObjectPose, WindowEstimate, WindowOptions, estimate_focal, estimate_poses,
                   interval_stabbing, solve_triplets, warm_up)

__version__ = "0.1.0"
__all__ = ["PAPER_FCOP_IS", "EstimatorOptions", "FocalEstimate", "FocalWindow", "NoiseBound",
           "ObjectPose", "WindowEstimate", "WindowOptions", "estimate_focal", "estimate_poses",
           "interval_stabbing", "solve_triplets", "warm_up"]
