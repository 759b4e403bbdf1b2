"""fcop_ros: camera focal length from category-level object priors (fCOP), as a library and a
ROS 2 node. Importing this package does not import rclpy, nor the estimator until one of its
names is used: the command-line entry points start light, so that Ctrl-C during their imports
ends them without a traceback."""
import importlib

__version__ = "0.1.0"
__all__ = ["PAPER_FCOP_IS", "EstimatorOptions", "FocalEstimate", "FocalWindow", "NoiseBound",
           "ObjectPose", "WindowEstimate", "WindowOptions", "estimate_focal", "estimate_poses",
           "interval_stabbing", "solve_triplets", "warm_up"]


def __getattr__(name):
    if name in __all__:
        return getattr(importlib.import_module(".core", __name__), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__():
    return sorted([*globals(), *__all__])
