"""fcop_ros: camera focal length from category-level object priors (fCOP), as a library and a
ROS 2 node. Importing this package does not import rclpy, nor the estimator until one of its
names (or a subpackage: ``fcop_ros.core``, ``.ros``, ``.tools``, ``.synthetic``) is used, so
that the command-line tools start light."""
from importlib import import_module as _import_module

__version__ = "0.1.0"
__all__ = ["PAPER_FCOP_IS", "EstimatorOptions", "FocalEstimate", "FocalWindow", "NoiseBound",
           "ObjectPose", "WindowEstimate", "WindowOptions", "estimate_focal", "estimate_poses",
           "interval_stabbing", "solve_triplets", "warm_up"]
_SUBPACKAGES = ("core", "ros", "tools", "synthetic")


def __getattr__(name):
    if name in __all__:
        value = getattr(_import_module(".core", __name__), name)
    elif name in _SUBPACKAGES:
        value = _import_module(f".{name}", __name__)
    else:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    globals()[name] = value  # resolved once; later lookups do not come here
    return value


def __dir__():
    return sorted({*globals(), *__all__, *_SUBPACKAGES})
