"""The estimator's and the window's settings as typed, frozen objects.

The node builds them once from its parameters (``fcop_ros/ros/params.py`` takes the defaults
of its option-backed parameters from here) and hands them to :func:`estimate_focal` and
:class:`FocalWindow`; tools and tests build them the same way. Each validates itself on
construction, so a wrong value fails where it is set, not deep in a frame.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .stabbing import focal_intervals

BOUND_MODES = ("relative", "absolute")
MAX_RELATIVE_BOUND = 0.5  # a relative noise bound is a fraction of f up to this
#: The focal lengths, pixels, a setting may name: the node's focal_min and focal_max, and the
#: synthetic sequences' focal (below 1 px their renderer overflows).
FOCAL_LIMITS = (1.0, 1e6)
# An erosion by a 3x3 square k times removes every object narrower than 2k + 1 pixels: beyond
# half the largest image side the package takes (8192, make_bag's) it removes every object, and
# its cost grows with k.
MAX_ERODE_PX = 4096
METHODS = ("stabbing", "ransac")


@dataclass(frozen=True)
class NoiseBound:
    """Half-width of every focal vote's interval in the stabbing: a fraction of f in log f
    ("relative", the same meaning at every focal length) or pixels ("absolute", the paper's)."""

    value: float = 0.05
    mode: str = "relative"

    def __post_init__(self):
        if self.mode not in BOUND_MODES:
            raise ValueError(f"noise bound mode must be one of {BOUND_MODES}, got {self.mode!r}")
        too_wide = self.mode == "relative" and not self.value <= MAX_RELATIVE_BOUND
        if not (self.value > 0 and np.isfinite(self.value)) or too_wide:
            raise ValueError(
                f"noise bound must be finite and > 0 (a fraction <= {MAX_RELATIVE_BOUND} when "
                "relative), "
                f"got {self.value}"
            )

    @property
    def equal_widths(self) -> bool:
        """True when every interval has one width (in log f): one sort of centres suffices."""
        return self.mode == "relative"

    @property
    def log_half_width(self) -> float:
        """The intervals' half-width in log f (relative mode only)."""
        return float(np.log1p(self.value))

    def intervals(self, votes: np.ndarray):
        """(lo, hi, back): each vote's interval in the stabbing's coordinate and the map back to
        pixels (see :func:`fcop_ros.core.stabbing.focal_intervals`)."""
        return focal_intervals(votes, self.value, self.mode)


@dataclass(frozen=True)
class EstimatorOptions:
    """How :func:`estimate_focal` turns one frame into a focal length (defaults: fcop_ros's).

    Votes: ``triplets_per_object`` random triplets on each object, each interval
    ``noise_bound`` wide; votes outside ``focal_range`` (px) are discarded and no focal outside it
    is reported. ``min_frame_votes`` agreeing votes (and ``min_inlier_ratio`` of them) are needed
    before a frame reports a focal length.

    Correspondences: instances with fewer than ``min_object_pixels`` usable pixels are ignored,
    only the ``max_instances`` largest are used; masks are eroded by ``erode_px``, correspondences
    averaged over ``denoise_radius``, pixels beyond ``outlier_sigma`` robust sigmas of their
    neighbourhood and depth edges beyond ``edge_sigma`` dropped (0: off), ``max_pixels`` kept per
    object.

    Per-object fit (``refine``): ``fit_pixels`` pixels, ``fit_iterations`` Gauss-Newton steps,
    each object's depth-error gradient fitted as a nuisance (``depth_tilt``). Objects whose NOCS
    explain less than ``min_fit_quality`` of their shape, or span less than ``min_nocs_spread``,
    are refused. The systematic error terms (:mod:`.error_model`): ``unseen_depth_error`` (the
    curvature of a smooth depth-error field, which the fit's tilt does not absorb, relative to
    the tilts it found, weighed by how much the object's fit leans on its depths),
    ``shape_error`` (per object, times the square root of its unexplained shape share beyond
    what noise explains), and a prior between-object spread ``object_tau`` (the spread that
    objects of one frame show beyond their own budgets, times the objects' rms derivative of
    log f by relief) worth ``object_tau_weight`` objects: a frame of one object, which no other
    can contradict, pays it whole. No pose for an object whose own std_rel exceeds
    ``pose_max_std``. ``principal_point_std``: how far the principal point, where it is assumed
    at the image centre, may be off (a fraction of the image's width and height, per axis): the
    prior of the offset the objects' disagreement shows, by which f is corrected; what remains
    uncertain of it widens std_rel through each object's gradient of f by the principal point.
    ``lens_distortion_std``: the standard deviation of the radial distortion k1 (x (1 + k1 r^2),
    r normalised by the focal length) that a rectified image still has: the prior of the k1 the
    objects' disagreement shows (:mod:`.lens`), by which f is corrected, as by the principal
    point's offset; what remains uncertain widens std_rel.

    ``method``: "stabbing" (triplet votes and interval stabbing, as the paper's fCOP-IS, then
    the refinement above unless ``refine=False``; ``PAPER_FCOP_IS`` is the paper's method taken
    literally) or "ransac" (fCOP-RANSAC, ``ransac_hypotheses``
    hypotheses, inlier threshold ``ransac_threshold`` relative to each object's median depth;
    the paper's is in metres, the same at 1 m).
    """

    triplets_per_object: int = 1500
    noise_bound: NoiseBound = field(default_factory=NoiseBound)
    focal_range: tuple[float, float] = (50.0, 20000.0)
    min_frame_votes: int = 30
    min_inlier_ratio: float = 0.05
    min_object_pixels: int = 50
    max_instances: int = 64
    erode_px: int = 1
    denoise_radius: int = 2
    outlier_sigma: float = 4.0
    edge_sigma: float = 2.0
    max_pixels: int = 2000
    refine: bool = True
    fit_pixels: int = 300
    fit_iterations: int = 10
    depth_tilt: bool = True
    min_fit_quality: float = 0.85
    min_nocs_spread: float = 0.1
    unseen_depth_error: float = 0.3
    shape_error: float = 0.1
    # The root-mean-square between-object spread (DerSimonian-Laird, at 0.005) of the tuning
    # world's multi-object `predicted` frames: `python bench/world_accuracy.py --frames 200
    # --parts tau --set object_tau=0.005` (docs/BENCHMARKS.md).
    object_tau: float = 0.066
    object_tau_weight: float = 2.0
    pose_max_std: float = 0.25
    # The rms of REAL275's camera's offsets (0.5% and 1.0% of width and height), the one real
    # camera the tuning world is calibrated against.
    principal_point_std: float = 0.0075
    # The tuning world's lens family (k1 uniform in +-0.01: 1.8 px at the corners of a 640x480
    # image at f = 600 px) has this standard deviation.
    lens_distortion_std: float = 0.0058
    method: str = "stabbing"
    ransac_hypotheses: int = 400
    ransac_threshold: float = 0.005

    def __post_init__(self):
        try:
            lo, hi = self.focal_range
        except (TypeError, ValueError):
            raise ValueError(f"focal_range must be (min, max) in pixels, got {self.focal_range!r}"
                             ) from None
        if not 0 < lo < hi:
            raise ValueError(f"focal_range must satisfy 0 < min < max, got {self.focal_range}")
        if self.method not in METHODS:
            raise ValueError(f"method must be one of {METHODS}, got {self.method!r}")
        if not isinstance(self.noise_bound, NoiseBound):
            raise TypeError("noise_bound must be a NoiseBound")
        for name, low in _EST_INTEGERS.items():
            _check_integer(self, name, low, _EST_INTEGER_TOPS.get(name))
        for name, (low, high) in _EST_NUMBERS.items():
            _check_number(self, name, low, high)
        for name in _EST_FINITE:
            if not np.isfinite(getattr(self, name)):
                raise ValueError(f"{name} must be finite (it enters every estimate's variance), "
                                 f"got {getattr(self, name)!r}")
        for name in ("refine", "depth_tilt"):
            if not isinstance(getattr(self, name), (bool, np.bool_)):
                raise TypeError(f"{name} must be True or False, got {getattr(self, name)!r}")


# Each setting's rule, so that a wrong value fails where it is set: integers at least this ...
_EST_INTEGERS = {
    "triplets_per_object": 1, "min_object_pixels": 1, "max_instances": 1, "max_pixels": 1,
    "fit_pixels": 1, "fit_iterations": 2, "ransac_hypotheses": 1, "min_frame_votes": 0,
    "erode_px": 0, "denoise_radius": 0,
}  # (fit_iterations: the last iteration only measures, so a single one fits nothing)
# ... and at most this.
_EST_INTEGER_TOPS = {"erode_px": MAX_ERODE_PX}
# ... and numbers within [low, high] (0 switches the outlier and edge tests off).
_EST_NUMBERS = {
    "min_inlier_ratio": (0.0, 1.0), "min_fit_quality": (0.0, 1.0),
    "min_nocs_spread": (0.0, np.inf), "outlier_sigma": (0.0, np.inf),
    "edge_sigma": (0.0, np.inf), "unseen_depth_error": (0.0, np.inf),
    "shape_error": (0.0, np.inf), "object_tau": (0.0, np.inf),
    "object_tau_weight": (0.0, np.inf), "pose_max_std": (0.0, np.inf),
    "principal_point_std": (0.0, 0.5), "lens_distortion_std": (0.0, 0.5),
    "ransac_threshold": (1e-12, np.inf),
}
# ... of which these must also be finite.
_EST_FINITE = ("unseen_depth_error", "shape_error", "object_tau", "object_tau_weight")


def _check_integer(options, name: str, low: int, high: int | None = None) -> None:
    """A ValueError unless ``options.name`` is an integer >= ``low`` (and <= ``high``, if given;
    not a bool or a float)."""
    v = getattr(options, name)
    top = np.inf if high is None else high
    if isinstance(v, (bool, np.bool_)) or not isinstance(v, (int, np.integer)) or not (
            low <= v <= top):
        rule = f">= {low}" if high is None else f"in [{low}, {high}]"
        raise ValueError(f"{name} must be an integer {rule}, got {v!r}")


def _check_number(options, name: str, low: float, high: float) -> None:
    """A ValueError unless ``options.name`` is a number in [low, high] (NaN is not)."""
    v = getattr(options, name)
    if isinstance(v, (bool, np.bool_)) or not isinstance(v, (int, float, np.number)) or not (
            low <= v <= high):
        raise ValueError(f"{name} must be a number in [{low:g}, {high:g}], got {v!r}")


@dataclass(frozen=True)
class WindowOptions:
    """How :class:`FocalWindow` combines frames (see :mod:`fcop_ros.core.window`).

    ``max_frames`` frames are kept, none older than ``max_age`` seconds (None: no limit); a focal
    is reported once ``min_frames`` frames had one and ``min_window_votes`` agreeing votes were
    seen over the window. Zoom detection: ``change_threshold`` (relative), ``change_sigma`` and
    ``change_frames``; frames beyond ``reject_sigma`` robust sigmas are left out.
    """

    max_frames: int = 30
    max_age: float | None = None
    min_frames: int = 1
    min_window_votes: int = 30
    change_threshold: float = 0.08
    change_sigma: float = 6.0
    change_frames: int = 3
    reject_sigma: float = 4.0

    def __post_init__(self):
        for name, low in (("max_frames", 1), ("min_frames", 1), ("min_window_votes", 0),
                          ("change_frames", 1)):
            _check_integer(self, name, low)
        if not 1 <= self.min_frames <= self.max_frames:
            raise ValueError("min_frames must be in 1..max_frames (the window holds no more)")
        if self.max_age is not None and not self.max_age > 0:
            raise ValueError("max_age must be > 0 seconds or None")
        if not (self.change_threshold > 0 and self.change_sigma > 0 and self.reject_sigma > 0):
            raise ValueError("change_threshold, change_sigma and reject_sigma must be > 0")


# The paper's fCOP-IS taken literally: uniform triplets on raw pixels, a 5 px bound, the
# interval midpoint, no refinement and no evidence threshold (it always answers).
PAPER_FCOP_IS = EstimatorOptions(
    noise_bound=NoiseBound(5.0, "absolute"),
    refine=False,
    denoise_radius=0,
    erode_px=0,
    outlier_sigma=0.0,
    edge_sigma=0.0,
    min_frame_votes=1,
    min_inlier_ratio=0.0,
    min_fit_quality=0.0,
    min_nocs_spread=0.0,
)
