"""The README and config/fcop.yaml describe the node as it is: every parameter, with its
default."""

import os
import re

import yaml

from fcop_ros.ros.params import PARAMETERS

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def test_config_file_sets_every_parameter_to_its_default():
    with open(os.path.join(ROOT, "config", "fcop.yaml")) as fh:
        params = yaml.safe_load(fh)["/**"]["ros__parameters"]  # any node name, any namespace
    assert set(params) == set(PARAMETERS)
    for name, spec in PARAMETERS.items():
        assert params[name] == spec.default and type(params[name]) is type(spec.default), name


def test_readme_parameter_table_lists_every_parameter_with_its_default():
    text = open(os.path.join(ROOT, "README.md")).read()
    rows = dict(re.findall(r"^\| `(\w+)` \| ([^|]+) \|", text, flags=re.M))
    for name, spec in PARAMETERS.items():
        default = spec.default
        assert name in rows, name
        shown = rows[name].strip()
        expected = (
            str(default).lower()
            if isinstance(default, bool)
            else str(default)
            if default != ""
            else '""'
        )
        assert shown == expected, (name, shown, expected)


def test_the_node_defaults_are_the_library_defaults():
    """The node's option-backed parameters take their defaults from fcop_ros.core.options: at
    their defaults it builds exactly the estimator's and the window's default settings."""
    from fcop_ros.core.options import EstimatorOptions, WindowOptions
    from fcop_ros.ros.params import defaults, estimator_options, window_options

    assert estimator_options(defaults()) == EstimatorOptions()
    assert window_options(defaults()) == WindowOptions()
