"""The Fast DDS set-up in one place: the shipped profile (large images across processes), how to
point at it, and how to keep a run's DDS traffic on this machine and out of other runs' way."""

from __future__ import annotations

import os
from contextlib import contextmanager
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


@contextmanager
def isolated(env=None):
    """While it lasts, ``env`` (default os.environ) has a run whose publishers and subscribers
    all live in this process (an offline replay) discover no other participant (Jazzy and
    later; Humble and Iron: this machine only) on a domain of its own from the process id,
    whatever the shell set, so that a live robot on the shell's domain neither disturbs it
    nor receives its messages. Yields the domain id; initialise rclpy within it (rcl reads the
    variables then), with ``rclpy.init(domain_id=...)``. The variables are restored after."""
    env = os.environ if env is None else env
    names = ("ROS_AUTOMATIC_DISCOVERY_RANGE", "ROS_LOCALHOST_ONLY", "ROS_STATIC_PEERS",
             "ROS_DOMAIN_ID")
    saved = {k: env.get(k) for k in names}
    try:
        if ros_distro() in ("humble", "iron"):
            env["ROS_LOCALHOST_ONLY"] = "1"
        else:
            env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "OFF"
            env.pop("ROS_LOCALHOST_ONLY", None)  # ahead of the range in Jazzy (above)
            env.pop("ROS_STATIC_PEERS", None)
        domain = 200 + os.getpid() % 30  # above the ids people use, within 232
        env["ROS_DOMAIN_ID"] = str(domain)
        yield domain
    finally:
        for k, v in saved.items():
            if v is None:
                env.pop(k, None)
            else:
                env[k] = v
