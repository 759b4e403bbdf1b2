"""The node's QoS: the profiles of its topics and what a QoS override may say.

Inputs take the sensor-data profile, outputs a reliable volatile one, ``~/latest_camera_info``
a latched one. Each call returns a new profile: rclpy writes a topic's QoS overrides into the
profile it is handed, so a shared one would carry an override over to every topic after it."""
from __future__ import annotations

import copy

from rclpy.qos import (
    DurabilityPolicy,
    HistoryPolicy,
    LivelinessPolicy,
    QoSProfile,
    ReliabilityPolicy,
    qos_profile_sensor_data,
)

# The words a QoS override of each policy takes (rclpy compares them in upper case).
QOS_WORDS = {
    name: tuple(m.lower() for m in policy.__members__ if m != "UNKNOWN")
    for name, policy in (
        ("reliability", ReliabilityPolicy),
        ("history", HistoryPolicy),
        ("durability", DurabilityPolicy),
        ("liveliness", LivelinessPolicy),
    )
}
# What a QoS override may change on the node's topics (QoSOverridingOptions'
# with_default_policies); rclpy declares no parameter for the other policies.
QOS_OVERRIDABLE = ("history", "depth", "reliability")
QOS_INTEGERS = {
    "depth": "an integer >= 0",
    "deadline": "an integer >= 0 (nanoseconds)",
    "lifespan": "an integer >= 0 (nanoseconds)",
    "liveliness_lease_duration": "an integer >= 0 (nanoseconds)",
}


def qos_override_problem(policy: str, value) -> str:
    """What is wrong with ``value`` as the QoS override of ``policy`` ('' if nothing)."""
    if policy in QOS_WORDS:
        ok = isinstance(value, str) and value.lower() in QOS_WORDS[policy]
        return "" if ok else "one of " + ", ".join(QOS_WORDS[policy])
    if policy in QOS_INTEGERS:
        ok = isinstance(value, int) and not isinstance(value, bool) and value >= 0
        return "" if ok else QOS_INTEGERS[policy]
    if policy == "avoid_ros_namespace_conventions":
        return "" if isinstance(value, bool) else "true or false"
    return ""


def refused_override(overrides: dict, prefix: str) -> str:
    """The first override under ``prefix`` ('qos_overrides.<topic>.<kind>.') that rclpy would
    refuse with a traceback, as 'parameter NAME=VALUE is not allowed: ...' ('' if none).
    ``overrides`` maps parameter names to rclpy Parameters."""
    for name, prm in overrides.items():
        policy = name[len(prefix):]
        if name.startswith(prefix) and policy in QOS_OVERRIDABLE:
            problem = qos_override_problem(policy, prm.value)
            if problem:
                return f"parameter {name}={prm.value!r} is not allowed: {problem}"
    return ""


def unknown_override_hint(name: str, topics) -> str:
    """What to say of a ``qos_overrides.`` parameter the node did not declare ('' if it is not
    one): which topics take overrides, or which policies they take."""
    if not name.startswith("qos_overrides."):
        return ""
    policy = name.rsplit(".", 1)[-1]
    if policy in QOS_OVERRIDABLE:
        return f" (the topics that take QoS overrides: {', '.join(topics)})"
    if policy in QOS_WORDS or policy in QOS_INTEGERS:
        return f" (QoS overrides take {', '.join(QOS_OVERRIDABLE)} here)"
    return ""


def input_qos() -> QoSProfile:
    """A new copy of rclpy's sensor-data profile: best effort, keep last 5, volatile."""
    return copy.copy(qos_profile_sensor_data)


def output_qos() -> QoSProfile:
    """A new profile of the outputs: reliable, volatile, keep last 10, spelled out (the "system
    default" profile leaves the durability to the RMW, and Fast DDS then makes the writer
    transient local)."""
    return QoSProfile(
        depth=10,
        history=HistoryPolicy.KEEP_LAST,
        reliability=ReliabilityPolicy.RELIABLE,
        durability=DurabilityPolicy.VOLATILE,
    )


def latched_qos() -> QoSProfile:
    """``~/latest_camera_info``'s profile: the newest message kept for late joiners."""
    return QoSProfile(
        depth=1,
        history=HistoryPolicy.KEEP_LAST,
        reliability=ReliabilityPolicy.RELIABLE,
        durability=DurabilityPolicy.TRANSIENT_LOCAL,
    )
