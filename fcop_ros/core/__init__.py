"""The fCOP estimator as plain numpy/scipy (no rclpy): solver, stabbing, correspondences,
per-object fits and their combination, frame estimate, poses and the sliding window."""

from .compiled import warm_up
from .correspondences import Instance, extract_instances
from .estimator import FocalEstimate, estimate_focal, estimate_poses
from .options import PAPER_FCOP_IS, EstimatorOptions, NoiseBound, WindowOptions
from .pose import ObjectPose, back_project, umeyama
from .solver import sample_triplets, solve_triplets
from .stabbing import StabbingResult, focal_intervals, interval_stabbing
from .window import FocalWindow, WindowEstimate

__all__ = [
    "Instance",
    "extract_instances",
    "EstimatorOptions",
    "NoiseBound",
    "WindowOptions",
    "PAPER_FCOP_IS",
    "FocalEstimate",
    "estimate_focal",
    "estimate_poses",
    "ObjectPose",
    "back_project",
    "umeyama",
    "sample_triplets",
    "solve_triplets",
    "StabbingResult",
    "focal_intervals",
    "interval_stabbing",
    "FocalWindow",
    "WindowEstimate",
    "warm_up",
]
