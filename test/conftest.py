"""Shared fixtures: rendered frames are cached per session because rendering dominates test time."""
import functools
import os

import numpy as np
import pytest

from fcop_ros.ros.dds import profile_env_vars, ros_distro

from fcop_ros.synthetic import apply_noise, render_scene

# Keep DDS traffic of every test on this machine and out of other runs' way, and use the
# shipped Fast DDS profile (large images across processes) in this process and its children.
# Set before any test initialises rclpy: Fast DDS reads the profile file once per process.
_CONFIG = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "config")
os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
if ros_distro() in ("humble", "iron"):  # no discovery range before Jazzy
    os.environ.setdefault("ROS_LOCALHOST_ONLY", "1")
# Jazzy still honours the deprecated ROS_LOCALHOST_ONLY, ahead of the discovery range, and then
# replaces the transports of the Fast DDS profile by UDP on loopback: 640x480 images sent
# best effort across processes got lost again (seen in CI). So it is not set from Jazzy on.
os.environ.setdefault("ROS_DOMAIN_ID", str(50 + os.getpid() % 150))
for _var in profile_env_vars():
    os.environ.setdefault(_var, os.path.join(_CONFIG, "fastdds_large_images.xml"))


@functools.lru_cache(maxsize=None)
def clean_frame(seed: int, width: int = 640, height: int = 480, focal=None):
    """A seeded random 5-object scene, rendered clean."""
    return render_scene(np.random.default_rng(seed), 5, focal, width, height)


@functools.lru_cache(maxsize=None)
def noisy_frame(seed: int, preset: str):
    return apply_noise(clean_frame(seed), preset, np.random.default_rng(10_000 + seed))


# Inputs that carry no focal evidence, as (depth, nocs, mask) -> None edits in place.
BAD_CASES = {
    "nan_depth": lambda d, n, m: d.fill(np.nan),
    "zero_depth": lambda d, n, m: d.fill(0.0),
    "inf_depth": lambda d, n, m: d.fill(np.inf),
    "empty_mask": lambda d, n, m: m.fill(0),
    "nocs_zero": lambda d, n, m: n.fill(0.0),
    "nocs_nan": lambda d, n, m: n.fill(np.nan),
    "single_pixel": lambda d, n, m: (m.fill(0), m.__setitem__((200, 300), 1)),
    "tiny_objects": lambda d, n, m: (m.fill(0), m.__setitem__((slice(100, 105), slice(100, 105)), 1)),
    "planar": lambda d, n, m: d.fill(1.0),  # every object flat at one depth: all triplets degenerate
}


def corrupted(frame, case):
    """A copy of a rendered frame with one of BAD_CASES applied."""
    from dataclasses import replace
    depth, nocs, mask = frame.depth.copy(), frame.nocs.copy(), frame.mask.copy()
    BAD_CASES[case](depth, nocs, mask)
    return replace(frame, depth=depth, nocs=nocs, mask=mask)


@pytest.fixture
def frames():
    return clean_frame, noisy_frame
