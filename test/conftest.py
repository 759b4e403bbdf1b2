"""The suite's environment (DDS kept on this machine, in a domain of its own, with the shipped
profile) and a per-test seeded generator. Scenes and bad inputs are in fcop_ros.synthetic.scenes,
the ROS harness (and its ``harness`` fixture, registered below) in ros_helpers."""
import os

import numpy as np
import pytest

from fcop_ros.dds import profile_env_vars, ros_distro

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

# The harness fixture, for every test without importing it by name (a name the test function's
# argument would shadow).
pytest_plugins = ["ros_helpers"]


@pytest.fixture
def rng():
    """A generator seeded afresh for every test: its data never depends on which tests ran."""
    return np.random.default_rng(0)
