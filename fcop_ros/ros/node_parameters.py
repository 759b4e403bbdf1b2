"""fcop_node's parameters on a node: declared from the table (:data:`.params.PARAMETERS`) with
rclpy's descriptors, a set request's integers taken for doubles as at start-up, and the names a
node does not have named with a hint. The table and its rules live in :mod:`.params`; this is
the part that needs the node."""
from __future__ import annotations

from rclpy.exceptions import ParameterException
from rclpy.parameter import Parameter

from .params import (
    PARAMETERS,
    ParameterError,
    allowed,
    as_declared,
    check_combination,
    check_words,
    descriptor,
    did_you_mean,
    not_allowed,
)
from .qos import unknown_override_hint


def given(node) -> dict:
    """The parameters given at start-up (``-p``, a params file), by name."""
    return getattr(node, "_parameter_overrides", {})


def declare(node) -> dict:
    """Declare every parameter with its descriptor and return their values. rclpy refuses a
    wrong type or range, turned here into one ParameterError line; then what descriptors cannot
    say (words, rules between parameters) is checked."""
    overrides = given(node)
    for name in PARAMETERS:
        prm = overrides.get(name)
        value = None if prm is None else as_declared(name, prm.value)
        if prm is not None and value is not prm.value:  # focal_min:=300 means 300.0
            overrides[name] = Parameter(name, value=value)
        try:
            declared = node.declare_parameter(name, PARAMETERS[name].default, descriptor(name))
        except ParameterException:
            value = overrides[name].value if name in overrides else "?"
            raise ParameterError(not_allowed(name, value, allowed(name, value))) from None
        if declared.type_ == Parameter.Type.NOT_SET:  # rcl's reading of '[]' or a blank
            raise ParameterError(f"parameter {name} has no value: {allowed(name)}")
    values = {name: node.get_parameter(name).value for name in PARAMETERS}
    for name, value in values.items():
        check_words(name, value)
    moved = {k for k, v in values.items() if v != PARAMETERS[k].default}
    problem = check_combination(values, changed=moved)
    if problem:
        raise ParameterError(problem)
    return values


def as_requested(params) -> list:
    """A set request's parameters, an integer for a double parameter taken as that double
    (``ros2 param set ... focal_min 300`` sends an integer; rclpy would refuse it by type)."""
    return [Parameter(prm.name, value=as_declared(prm.name, prm.value))
            if prm.name in PARAMETERS and prm.type_ == Parameter.Type.INTEGER else prm
            for prm in params]


def unknown_hint(name: str, topic_names) -> str:
    """' (did you mean ...?)' for a parameter name a node does not have, or '': the nearest
    parameter, or for a ``qos_overrides.`` name the topics (``topic_names``) that take them."""
    return unknown_override_hint(name, topic_names) or did_you_mean(name)
