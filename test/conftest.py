"""Shared fixtures: rendered frames are cached per session because rendering dominates test time."""
import functools
import os

import numpy as np
import pytest

from fcop_ros.dds import profile_env_vars

from fcop_ros.synthetic import apply_noise, render_scene

# Keep DDS traffic of every test on this machine and out of other runs' way, and use the
# shipped Fast DDS profile (large images across processes) in this process and its children.
# Set before any test initialises rclpy: Fast DDS reads the profile file once per process.
_CONFIG = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "config")
os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
os.environ.setdefault("ROS_LOCALHOST_ONLY", "1")
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


@pytest.fixture
def frames():
    return clean_frame, noisy_frame
