"""fcop_node's parameters: one table of named specs, their rclpy descriptors, and the rules.

The table is the one place a parameter's default, meaning and allowed values are written; the
node declares from it, fcop_replay checks a params file against it, and the tests check
config/fcop.yaml and the README against it. rclpy enforces what a descriptor can say (type,
numeric range, read-only) before any on-set callback runs; what it cannot say (a choice among
words, a text rule) and the rules between parameters are checked here. No rclpy import.
"""

from __future__ import annotations

import difflib
import operator
import re
from dataclasses import dataclass

from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor

from ..core.options import (
    BOUND_MODES,
    FOCAL_LIMITS,
    MAX_RELATIVE_BOUND,
    EstimatorOptions,
    NoiseBound,
    WindowOptions,
)

NOCS_CONVENTIONS = ("fcop", "nocs_dataset")
# The estimator's and the window's defaults, written once (in fcop_ros/core/options.py).
_EST, _WIN = EstimatorOptions(), WindowOptions()
_NAME = re.compile(r"[A-Za-z0-9_-]+")


class ParameterError(ValueError):
    """A parameter value fcop_node cannot run with; the message names it, its value and what
    is allowed."""


@dataclass(frozen=True)
class ParamSpec:
    """One parameter: its default (whose type is the parameter's type), a description, and at
    most one of a numeric range, a set of choices or a text rule; ``read_only`` parameters are
    set at start-up only."""

    default: bool | int | float | str
    description: str
    range: tuple | None = None  # (min, max), both inclusive, for int and float parameters
    choices: tuple = ()  # allowed words of a string parameter
    text_rule: str = ""  # a rule a string must follow, in words (checked in check_value)
    read_only: bool = False


PARAMETERS: dict[str, ParamSpec] = {
    "window_frames": ParamSpec(
        _WIN.max_frames, "Frames in the sliding window of focal evidence.", range=(1, 1000)
    ),
    "window_seconds": ParamSpec(
        0.0,
        "Also forget frames older than this many seconds (0 = no age limit).",
        range=(0.0, 3600.0),
    ),
    "triplets_per_object": ParamSpec(
        _EST.triplets_per_object,
        "Random triplets drawn on each object per frame.",
        range=(10, 100000),
    ),
    "noise_bound": ParamSpec(
        _EST.noise_bound.value,
        "Stabbing half-width: a fraction of f (relative mode) or pixels (absolute).",
        range=(1e-4, 1000.0),
    ),
    "noise_bound_mode": ParamSpec(
        _EST.noise_bound.mode,
        "'relative' (log f, same meaning at every focal) or 'absolute' (pixels).",
        choices=BOUND_MODES,
    ),
    "focal_min": ParamSpec(
        _EST.focal_range[0], "Smallest focal length considered, pixels.", range=FOCAL_LIMITS
    ),
    "focal_max": ParamSpec(
        _EST.focal_range[1], "Largest focal length considered, pixels.", range=FOCAL_LIMITS
    ),
    "min_object_pixels": ParamSpec(
        _EST.min_object_pixels,
        "Instances with fewer usable pixels are ignored.",
        range=(3, 10000000),
    ),
    "depth_scale": ParamSpec(
        0.001,
        "Metres per unit of 16UC1 depth images (REP-118: millimetres).",
        range=(1e-9, 1000.0),
    ),
    "principal_point_x": ParamSpec(
        -1.0,
        "cx in pixels (inside the image); negative = from camera_info_in, else the image "
        "centre (W-1)/2.",
        range=(-1.0, 1e6),
    ),
    "principal_point_y": ParamSpec(
        -1.0,
        "cy in pixels (inside the image); negative = from camera_info_in, else the image "
        "centre (H-1)/2.",
        range=(-1.0, 1e6),
    ),
    "principal_point_std": ParamSpec(
        0.0075,
        "How far the principal point may be off the image centre where it is assumed there "
        "(no principal_point_x/y, no camera_info_in), a fraction of the image's width and "
        "height: the prior of the offset the objects show, which corrects the focal length; "
        "what remains uncertain widens the reported uncertainty (0: neither).",
        range=(0.0, 0.5),
    ),
    "lens_distortion_std": ParamSpec(
        0.0058,
        "How much radial distortion k1 (x (1 + k1 r^2), r normalised by the focal length) the "
        "rectified images may still have: the prior of the k1 the objects' disagreement shows, "
        "by which the focal length is corrected; what remains uncertain widens the reported "
        "uncertainty (0: a perfect lens, not estimated).",
        range=(0.0, 0.5),
    ),
    "sync_mode": ParamSpec(
        "exact",
        "'exact' (equal stamps) or 'approximate' (within sync_slop).",
        choices=("exact", "approximate"),
    ),
    "sync_slop": ParamSpec(
        0.01,
        "Largest stamp difference within a frame in approximate mode, seconds.",
        range=(0.0, 1.0),
    ),
    "queue_size": ParamSpec(
        5,
        "Messages per input waiting in the synchroniser for the other inputs: more than the "
        "latest input's delay behind the others times their rate.",
        range=(1, 100),
    ),
    "publish_poses": ParamSpec(True, "Publish object_poses (geometry_msgs/PoseArray)."),
    "publish_markers": ParamSpec(True, "Publish object_markers (visualization_msgs/MarkerArray)."),
    "min_frames": ParamSpec(
        _WIN.min_frames,
        "Frames the window needs before it reports a focal length.",
        range=(1, 1000),
    ),
    "min_window_votes": ParamSpec(
        _WIN.min_window_votes,
        "Agreeing triplet votes, summed over the window's frames, the window needs before it "
        "reports a focal length.",
        range=(1, 10000000),
    ),
    "max_uncertainty": ParamSpec(
        0.05,
        "Largest relative standard error (std_rel) of the window's focal length at which "
        "CameraInfo is published and a calibration saved.",
        range=(1e-6, 1.0),
    ),
    "diagnostics_period": ParamSpec(
        1.0, "Seconds between /diagnostics messages.", range=(0.05, 60.0)
    ),
    "max_estimate_age": ParamSpec(
        2.0,
        "Diagnostics go ERROR when the estimator has been busy with one frame for longer "
        "than this many seconds (stalled).",
        range=(0.1, 3600.0),
    ),
    "nocs_convention": ParamSpec(
        "fcop",
        "Axes of the NOCS input: 'fcop' (this package's) or 'nocs_dataset' (the NOCS "
        "dataset's: z = 1 - z).",
        choices=NOCS_CONVENTIONS,
    ),
    "camera_name": ParamSpec(
        "camera",
        "Camera name in the file ~/save_calibration writes.",
        text_rule="letters, digits, _ and -",
    ),
    "calibration_file": ParamSpec(
        "",
        "File ~/save_calibration writes ('' = ~/.ros/camera_info/<camera_name>.yaml).",
        text_rule="a file path",
    ),
    "set_camera_info_service": ParamSpec(
        "",
        "sensor_msgs/srv/SetCameraInfo service ~/save_calibration also calls, e.g. the "
        "driver's set_camera_info ('' = none). Read-only.",
        text_rule="a service name",
        read_only=True,
    ),
    "seed": ParamSpec(
        -1,
        "Random seed of triplet sampling (-1 = from the OS). Read-only.",
        range=(-1, 2**31 - 1),
        read_only=True,
    ),
}
# Set once at start-up: refused at run time (the descriptor says read_only).
READ_ONLY = frozenset(name for name, spec in PARAMETERS.items() if spec.read_only)


def estimator_options(p: dict) -> EstimatorOptions:
    """The estimator's settings from a complete set of parameter values."""
    return EstimatorOptions(
        triplets_per_object=p["triplets_per_object"],
        noise_bound=NoiseBound(p["noise_bound"], p["noise_bound_mode"]),
        focal_range=(p["focal_min"], p["focal_max"]),
        min_object_pixels=p["min_object_pixels"],
        lens_distortion_std=p["lens_distortion_std"],
    )


def window_options(p: dict) -> WindowOptions:
    """The window's settings from a complete set of parameter values (window_seconds 0: no age
    limit)."""
    return WindowOptions(
        max_frames=p["window_frames"],
        max_age=p["window_seconds"] or None,
        min_frames=p["min_frames"],
        min_window_votes=p["min_window_votes"],
    )


def sync_settings(p: dict) -> tuple:
    """The synchroniser's (queue_size, slop in seconds; 0 = exact matching)."""
    queue_size, slop, mode = p["queue_size"], p["sync_slop"], p["sync_mode"]
    return queue_size, (slop if mode == "approximate" else 0.0)


def gate_settings(p: dict) -> tuple:
    """The publish gate's (max_uncertainty, (focal_min, focal_max))."""
    return p["max_uncertainty"], (p["focal_min"], p["focal_max"])


def defaults() -> dict:
    """{name: default} of every parameter."""
    return {name: spec.default for name, spec in PARAMETERS.items()}


class _Reads(dict):
    """Parameter values that note which of them a builder reads."""

    def __init__(self, values):
        super().__init__(values)
        self.read = set()

    def __getitem__(self, name):
        self.read.add(name)
        return super().__getitem__(name)


def _read_by(build, values: dict | None = None) -> frozenset:
    """The parameters ``build`` reads from ``values`` (the defaults); builders read every
    parameter they depend on whatever the values, so that this finds them all."""
    values = _Reads(defaults() if values is None else values)
    build(values)
    return frozenset(values.read)


# Which run-time changes rebuild the estimator's options, the window, the publish gate or the
# synchroniser: the parameters their builders read, so none can be wired into a builder and
# left out here.
ESTIMATOR_PARAMETERS = _read_by(estimator_options)
WINDOW_PARAMETERS = _read_by(window_options)
GATE_PARAMETERS = _read_by(gate_settings)
SYNC_PARAMETERS = _read_by(sync_settings)


def allowed(name: str, value=None) -> str:
    """What parameter ``name`` accepts, in words; for a string parameter given a number or a
    bool (``-p camera_name:=1``), how to give that as text."""
    spec = PARAMETERS[name]
    if isinstance(spec.default, bool):
        return "true or false"
    if spec.choices:
        return "one of " + ", ".join(spec.choices)
    if spec.range is not None:
        kind = "an integer" if isinstance(spec.default, int) else "a number"
        return f"{kind} in [{spec.range[0]}, {spec.range[1]}]"
    words = f"a string ({spec.text_rule})"
    if value is not None and not isinstance(value, str):
        words += ("; ROS reads a bare number or yes/no/true/false as that type, so quote text "
                  f"(-p {name}:=\"'text'\", or 'text' in a params file)")
    return words


def descriptor(name: str) -> ParameterDescriptor:
    """The rclpy descriptor of parameter ``name``: description, read_only and numeric range (which
    rclpy enforces), and the choices or text rule as additional_constraints (which it shows)."""
    spec = PARAMETERS[name]
    d = ParameterDescriptor(name=name, description=spec.description, read_only=spec.read_only)
    if (
        spec.range is not None
        and isinstance(spec.default, int)
        and not isinstance(spec.default, bool)
    ):
        d.integer_range = [
            IntegerRange(from_value=int(spec.range[0]), to_value=int(spec.range[1]), step=1)
        ]
    elif spec.range is not None:
        d.floating_point_range = [
            FloatingPointRange(from_value=float(spec.range[0]), to_value=float(spec.range[1]))
        ]
    elif spec.choices:
        d.additional_constraints = "one of: " + ", ".join(spec.choices)
    elif spec.text_rule:
        d.additional_constraints = spec.text_rule
    return d


def as_declared(name: str, value):
    """``value`` as the parameter ``name`` holds it: an integer given for a double parameter is
    that double (``focal_min:=300`` and ``ros2 param set ... focal_min 300`` mean 300.0)."""
    default = PARAMETERS[name].default
    if isinstance(default, float) and isinstance(value, int) and not isinstance(value, bool):
        return float(value)
    return value


def not_allowed(name: str, value, rule: str, source: str = "") -> str:
    """The one wording of a refused value: 'parameter NAME=VALUE [from SOURCE] is not allowed:
    RULE' (the source: where a tool read it, e.g. a params file or -p)."""
    where = f" from {source}" if source else ""
    return f"parameter {name}={value!r}{where} is not allowed: {rule}"


def did_you_mean(name: str) -> str:
    """' (did you mean X?)' for the parameter nearest a name the node does not have, or ''."""
    close = difflib.get_close_matches(name, list(PARAMETERS), n=1)
    return f" (did you mean {close[0]}?)" if close else ""


def check_value(name: str, value):
    """``value`` converted to the parameter's type (an integer for a double is taken), or
    ParameterError naming name, value and what is allowed. Checks type and range as well as what
    a descriptor cannot say, for values that did not pass through rclpy (start-up, tools)."""
    spec = PARAMETERS[name]
    value = as_declared(name, value)
    if type(value) is not type(spec.default):
        raise ParameterError(not_allowed(name, value, allowed(name, value)))
    if isinstance(value, bool):
        ok = True
    elif spec.choices:
        ok = value in spec.choices
    elif spec.range is not None:
        ok = spec.range[0] <= value <= spec.range[1]
    elif name == "camera_name":
        ok = bool(_NAME.fullmatch(value))
    else:
        ok = "\n" not in value
    if not ok:
        raise ParameterError(not_allowed(name, value, allowed(name)))
    return value


def check_words(name: str, value) -> None:
    """ParameterError if a string parameter's value breaks what its descriptor cannot enforce
    (a choice among words, a text rule); rclpy has already checked its type."""
    spec = PARAMETERS[name]
    if spec.choices or spec.text_rule:
        check_value(name, value)


# Pairs of parameters one of which bounds the other: (lower, upper, the rule between their
# values, the rule in words for each).
_ORDERED_PAIRS = (
    ("focal_min", "focal_max", operator.lt, "below", "above"),
    ("min_frames", "window_frames", operator.le, "at most", "at least"),
)


def combination_conflict(p: dict, image_size=None, changed=()) -> tuple[str, str]:
    """The parameter to blame for what is wrong with a complete set of values together and the
    rule it breaks (('', '') if nothing); ``image_size`` (width, height), once known, bounds
    the principal point. Of two parameters in conflict, the one being ``changed`` is blamed
    (the first of the pair if both or neither)."""
    for low, high, holds, low_rule, high_rule in _ORDERED_PAIRS:
        if holds(p[low], p[high]):
            continue
        if high in changed and low not in changed:
            return high, f"it must be {high_rule} {low}={p[low]}"
        return low, f"it must be {low_rule} {high}={p[high]}"
    if p["noise_bound_mode"] == "relative" and not 0 < p["noise_bound"] <= MAX_RELATIVE_BOUND:
        if "noise_bound_mode" in changed and "noise_bound" not in changed:
            return ("noise_bound_mode", f"noise_bound={p['noise_bound']:g} is no fraction in "
                    f"(0, {MAX_RELATIVE_BOUND}]: set noise_bound first")
        return ("noise_bound",
                f"a fraction in (0, {MAX_RELATIVE_BOUND}] in relative noise_bound_mode")
    if image_size is not None:
        for axis, size in (("x", image_size[0]), ("y", image_size[1])):
            v = p[f"principal_point_{axis}"]
            if v >= 0 and not v <= size - 1:
                return (f"principal_point_{axis}", f"inside the {image_size[0]}x{image_size[1]} "
                        f"image, [0, {size - 1}] (or negative for the default)")
    return "", ""


def check_combination(p: dict, image_size=None, changed=()) -> str:
    """combination_conflict in one line ('' if nothing is wrong)."""
    name, rule = combination_conflict(p, image_size, changed)
    return not_allowed(name, p[name], rule) if name else ""
