"""The suite's environment (DDS kept on this machine, in a domain of its own, with the shipped
profile) and a per-test seeded generator. Scenes and bad inputs are in fcop_ros.synthetic.scenes,
the ROS harness (and its ``harness`` fixture, registered below) in ros_helpers."""

import numpy as np
import pytest

from fcop_ros.ros.dds import keep_on_this_machine, use_large_image_profile

# Keep DDS traffic of every test on this machine and out of other runs' way (a developer's
# ROS_LOCALHOST_ONLY is dropped from Jazzy on: the start-up tests count stderr lines), and use
# the shipped Fast DDS profile (large images across processes) in this process and its children.
# Set before any test initialises rclpy: Fast DDS reads the profile file once per process.
keep_on_this_machine()
use_large_image_profile()

# The harness fixture, for every test without importing it by name (a name the test function's
# argument would shadow).
pytest_plugins = ["ros_helpers"]


@pytest.fixture
def rng():
    """A generator seeded afresh for every test: its data never depends on which tests ran."""
    return np.random.default_rng(0)
