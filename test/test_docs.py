"""The README and config/fcop.yaml describe the node as it is: every parameter, with its
default and its range or choices, and every value of its /diagnostics status; docs/DESIGN.md
names files and names that exist."""

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


def _number(text: str) -> float:
    return float(text.replace("2³¹-1", str(2**31 - 1)))


def test_readme_parameter_table_gives_each_range_and_choice_as_the_node_enforces_it():
    text = open(os.path.join(ROOT, "README.md")).read()
    rows = dict(re.findall(r"^\| `(\w+)` \|[^|]+\|([^|]*)\|", text, flags=re.M))
    for name, spec in PARAMETERS.items():
        shown = rows[name].strip()
        if spec.range is not None:
            low, high = shown.split(",")[0].split(" .. ")
            assert (_number(low), _number(high)) == tuple(map(float, spec.range)), (name, shown)
        elif spec.choices:
            assert shown == " / ".join(spec.choices), (name, shown)
        elif isinstance(spec.default, bool):
            assert shown == "", (name, shown)


def test_readme_lists_every_diagnostics_value_the_node_sends():
    from fcop_ros.core import WindowEstimate
    from fcop_ros.ros.diagnostics import DiagnosticsInput, Rates, status_fields

    reading = DiagnosticsInput(
        now=1.0, window_estimate=WindowEstimate(600.0, std_rel=0.01, support=50, frames=3),
        publishable=True, window_fill="3/30", max_uncertainty=0.05, max_estimate_age=2.0,
        matched=3, processed=3, skipped=0, sync_dropped=0, camera_info_published=3,
        input_ages=(("depth", 0.01), ("nocs", 0.02), ("mask", 0.02)))
    sent = set(status_fields(reading, Rates(5.0, 3, 3, 0))[2])
    text = open(os.path.join(ROOT, "README.md")).read()
    listed = text[text.index("Values:\n`focal_px`"):].split("\n\n")[0]
    named = set(re.findall(r"`(\w+)`", listed)) - {"dropped_", "warning_"}
    assert named == sent, (sorted(sent - named), sorted(named - sent))
    assert "`dropped_<reason>`" in listed and "`warning_<reason>`" in listed


def test_the_node_defaults_are_the_library_defaults():
    """The node's option-backed parameters take their defaults from fcop_ros.core.options: at
    their defaults it builds exactly the estimator's and the window's default settings."""
    from fcop_ros.core.options import EstimatorOptions, WindowOptions
    from fcop_ros.ros.params import defaults, estimator_options, window_options

    assert estimator_options(defaults()) == EstimatorOptions()
    assert window_options(defaults()) == WindowOptions()


def test_design_owner_table_names_files_and_names_that_exist():
    """docs/DESIGN.md's 'Who owns what': every file it lists exists and every name it gives a
    file occurs in that file (a newcomer's review found a function renamed away, stop 27)."""
    text = open(os.path.join(ROOT, "docs", "DESIGN.md")).read()
    table = text.split("## Who owns what")[1].split("\n## ")[0]
    rows = re.findall(r"^\| `([^`]+)` \| (.*) \|$", table, re.M)
    assert len(rows) > 40
    wrong = []
    for path, owns in rows:
        if not os.path.isfile(os.path.join(ROOT, path)):
            wrong.append(f"{path}: no such file")
            continue
        source = open(os.path.join(ROOT, path)).read()
        wrong += [f"{path}: no {name}" for name in re.findall(r"`([A-Za-z_]\w*)`", owns)
                  if not re.search(rf"\b{name}\b", source)]
    assert not wrong, wrong


def test_readme_lists_every_reason_the_node_counts_a_drop_by():
    """The README's table of drop reasons (`dropped_<reason>` in /diagnostics) against the
    reasons the code counts: the synchroniser's drops (sync_<reason>, outlier_stamp_<input>),
    the refusals of a frame (Refused subclasses) and the node's own counters."""
    from fcop_ros.ros.topics import INPUTS

    text = open(os.path.join(ROOT, "README.md")).read()
    table = text.split("| case | reason counted |")[1].split("\n\n")[0]
    documented = set(re.findall(r"`([a-z_]+)`", "\n".join(
        row.rsplit("|", 2)[1] for row in table.splitlines()[2:])))
    ros = os.path.join(ROOT, "fcop_ros", "ros")
    code = "".join(open(os.path.join(ros, name)).read() for name in sorted(os.listdir(ros))
                   if name.endswith(".py"))
    counted = {f"sync_{r}" for r in re.findall(r'stats\.drop\("([a-z_]+)"', code)}
    counted.discard("sync_outlier_stamp")
    counted |= {f"outlier_stamp_{i}" for i in INPUTS}
    counted |= set(re.findall(r'Refused\(\s*"([a-z_]+)"', code))
    counted |= set(re.findall(r'(?<!stats\.)(?:rejected|dropped)\["([a-z_]+)"\]', code))
    counted |= set(re.findall(r'(?:_reject|no_focal)\("([a-z_]+)"', code))
    assert documented == counted, (sorted(documented - counted), sorted(counted - documented))
