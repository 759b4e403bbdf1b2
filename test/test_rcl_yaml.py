"""The replay types parameter values as rcl does: checked against rcl itself, through rclpy's
parameter overrides, on values where YAML 1.1, Python and C disagree."""

import math
import re

import pytest

from fcop_ros.tools import rcl_yaml
from ros_helpers import ros_context

# Each of these once typed differently in the replay than in the node (Python's int() takes
# '1_000' and Arabic digits, PyYAML 1.1 makes '2024-01-01' a date and '010' ten), or is an
# edge of C's strtoll/strtod that rcl inherits (octal, hex floats, ERANGE keeps the text).
VALUES = [
    "0", "-0", "1_000", "٣", "2024-01-01", "08", "0x1p3", "1e400", "1e-310", "1e-400",
    "1e-320", "0x10", "010", "+5", "5 ", "-0x10", "0X1F", "9223372036854775808",
    "-9223372036854775808",
    "Y", "n", "yes", "Off", "'yes'", '"1"', "!!str 5", ".Inf", "-.inf", ".NaN", "nan",
    "infinity", "Nan(abc)", "1.", ".5", "1e", "0x", "1e5", "~", "null", "0o17", "0b1", "1,5",
    "+", "'a b'", "a b", "[1, 2]", "[yes, no]", "['1', x]", "[0.5, 1e3]",
]

RCL_TYPES = {"BOOL": bool, "INTEGER": int, "DOUBLE": float, "STRING": str,
             "INTEGER_ARRAY": list, "BOOL_ARRAY": list, "DOUBLE_ARRAY": list,
             "STRING_ARRAY": list}


def rcl_values(values) -> list:
    """(type name, value) of each value as rcl parsed it from ``-p pN:=value``."""
    from rclpy.node import Node
    args = ["fcop_node", "--ros-args"]
    for i, text in enumerate(values):
        args += ["-p", f"p{i}:={text}"]
    with ros_context(args) as (ctx, _):
        node = Node("fcop_node", context=ctx)
        try:
            got = node._parameter_overrides
            return [(got[f"p{i}"].type_.name, got[f"p{i}"].value) for i in range(len(values))]
        finally:
            node.destroy_node()


def same(a, b) -> bool:
    if isinstance(a, list):
        return len(a) == len(b) and all(same(x, y) for x, y in zip(a, b))
    return type(a) is type(b) and (a == b or (isinstance(a, float) and math.isnan(a)
                                               and math.isnan(b)))


def test_values_typed_as_rcl_types_them():
    for text, (kind, value) in zip(VALUES, rcl_values(VALUES)):
        mine = rcl_yaml.load(text)
        expected = list(value) if kind.endswith("ARRAY") else value
        assert isinstance(mine, RCL_TYPES[kind]) and same(mine, expected), (text, kind, value,
                                                                              mine)


@pytest.mark.parametrize("text, problem", [
    ("[1, 2.0]", "of one type"),
    ("[[1], [2]]", "only values"),
    ("window_frames:\n", "has no value (line 1)"),
])
def test_what_rcl_refuses_is_refused(text, problem):
    with pytest.raises(rcl_yaml.RclYamlError, match=re.escape(problem)):
        rcl_yaml.load(text)


@pytest.mark.parametrize("text, problem", [
    ("[]", "has no value"),          # rcl leaves the parameter unset
    ("|\n", "has no value"),         # an empty block scalar: rcl's "No value"
    ("[&a 1, *a]", "rcl does not take aliases"),
])
def test_what_rcl_leaves_unset_or_refuses_has_no_value(text, problem):
    with pytest.raises(rcl_yaml.RclYamlError, match=re.escape(problem)):
        rcl_yaml.load(text)


def test_params_file_entries_in_the_order_rcl_applies_them():
    text = ("a:\n  ros__parameters:\n    x: 1\n    n: {y: 2.0, z: [1, 2]}\n"
            "/**:\n  ros__parameters:\n    x: 'text'\n---\na:\n  ros__parameters:\n    x: 3\n")
    assert rcl_yaml.parameter_entries(text) == [
        ("a", "x", 1), ("a", "n.y", 2.0), ("a", "n.z", [1, 2]), ("/**", "x", "text"),
        ("a", "x", 3)]
