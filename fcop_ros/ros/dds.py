"""The Fast DDS set-up in one place: the shipped profile (large images across processes), how to
point at it, and how to keep a run's DDS traffic on this machine and out of other runs' way."""

from __future__ import annotations

import os
from importlib import metadata

from .config import config_path


def ros_distro() -> str:
    """The ROS 2 distribution in use: $ROS_DISTRO on a ROS machine, else from the PyPI wheels."""
    distro = os.environ.get("ROS_DISTRO", "")
    if distro:
        return distro
    try:
        metadata.version("ros-jazzy-rclpy")
        return "jazzy"
    except metadata.PackageNotFoundError:
        return "kilted"


def profile_env_vars() -> tuple[str, ...]:
    """Environment variables that name the default profiles file for the installed Fast DDS:
    Humble to Jazzy (Fast DDS 2) read FASTRTPS_DEFAULT_PROFILES_FILE, Kilted (Fast DDS 3) the
    FASTDDS one and warns that the other is deprecated."""
    if ros_distro() in ("humble", "iron", "jazzy"):
        return ("FASTRTPS_DEFAULT_PROFILES_FILE", "FASTDDS_DEFAULT_PROFILES_FILE")
    return ("FASTDDS_DEFAULT_PROFILES_FILE",)


def large_image_profile() -> str:
    """Path of config/fastdds_large_images.xml (installed share/ or the source tree)."""
    return config_path("fastdds_large_images.xml")


def use_large_image_profile(env=None) -> dict:
    """Point ``env`` (default os.environ) at the shipped profile unless already set; return it.
    Must happen before the process initialises rclpy."""
    env = os.environ if env is None else env
    for var in profile_env_vars():
        env.setdefault(var, large_image_profile())
    return env


def keep_on_this_machine(env=None, domain_id: int | None = None) -> dict:
    """Keep DDS discovery on this machine and give the run a domain of its own (default: from
    the process id), in ``env`` (default os.environ) unless already set; return it. From Jazzy
    on, a ROS_LOCALHOST_ONLY already set is removed (below). Must happen before the process
    initialises rclpy; child processes inherit it."""
    env = os.environ if env is None else env
    env.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    if ros_distro() in ("humble", "iron"):  # no discovery range before Jazzy
        env.setdefault("ROS_LOCALHOST_ONLY", "1")
    else:
        # Jazzy still honours the deprecated ROS_LOCALHOST_ONLY, ahead of the discovery range,
        # and then replaces the transports of the Fast DDS profile by UDP on loopback: 640x480
        # images sent best effort across processes got lost again (seen in CI). rcl also warns
        # of it at every process start (one more stderr line). So it is not kept from Jazzy.
        env.pop("ROS_LOCALHOST_ONLY", None)
    env.setdefault(
        "ROS_DOMAIN_ID", str(50 + os.getpid() % 150 if domain_id is None else domain_id)
    )
    return env
