"""fcop_replay's node parameters: ROS 2 parameter-file sections for any namespace, then every
-p NAME:=VALUE, checked against fcop_node's parameter table before anything runs."""

from __future__ import annotations

from pathlib import Path

import yaml

from ..ros.config import config_path
from . import rcl_yaml
from .replay_base import ReplayError

NODE_NAME = "fcop_node"


_ROS_PARAMETERS = ("use_sim_time", "start_type_description_service")


def _applies(key: str, node_name: str) -> bool:
    """Does a parameter-file section apply to the replayed node? Its last name must be the node's
    or a wildcard: the namespace part is ignored, because the replayed node stands in for the
    user's node wherever that runs ('/**', '/**/fcop_node', 'fcop_node', '/camera/fcop_node')."""
    last = key.strip("/").split("/")[-1] if key.strip("/") else ""
    return last in (node_name, "*", "**")


def load_params_file(path, node_name: str = NODE_NAME) -> dict:
    """{name: value} of every section of a ROS 2 parameter file that applies to ``node_name``
    (see :func:`_applies`), in the order rcl applies them: file order, a later value winning."""
    try:
        text = Path(path).read_text(encoding="utf-8")
    except OSError as exc:
        raise ReplayError(f"cannot read --params-file {path}: {exc.strerror or exc}") from None
    except UnicodeDecodeError as exc:  # a binary file, or another encoding: rcl reads UTF-8
        byte = exc.object[exc.start]
        raise ReplayError(f"--params-file {path} is not UTF-8 text (byte 0x{byte:02x} at offset "
                          f"{exc.start}); a ROS 2 parameter file is UTF-8 YAML") from None
    try:
        entries = rcl_yaml.parameter_entries(text)
    except yaml.YAMLError as exc:
        where = getattr(exc, "problem_mark", None)
        at = f" (line {where.line + 1})" if where is not None else ""
        raise ReplayError(
            f"--params-file {path} is not valid YAML{at}: {getattr(exc, 'problem', exc)}"
        ) from None
    except rcl_yaml.RclYamlError as exc:
        raise ReplayError(f"--params-file {path}: {exc}") from None
    if not entries:
        raise ReplayError(
            f"--params-file {path} is not a ROS 2 parameter file "
            f"(expected '/**:' or '{node_name}:' with 'ros__parameters:' under it)"
        )
    values = {name: value for section, name, value in entries if _applies(section, node_name)}
    if not values:
        sections = dict.fromkeys(section for section, _, _ in entries)
        raise ReplayError(
            f"--params-file {path} has no section for {node_name} (it has: "
            f"{', '.join(sections)}); key it '/**:' or '{node_name}:'"
        )
    return values


def parse_value(text: str, name: str = "NAME"):
    """A -p value typed as rcl types it (see rcl_yaml): bool words, C integers and doubles,
    [lists] of one type, quoted text, else text."""
    try:
        value = rcl_yaml.load(text, f"-p {name}")
    except yaml.YAMLError as exc:
        raise ReplayError(f"-p {name}:={text} is not a YAML value: "
                          f"{getattr(exc, 'problem', exc)}") from None
    except rcl_yaml.RclYamlError as exc:
        raise ReplayError(str(exc)) from None
    if value is None:
        raise ReplayError(f"-p {name}:={text} has no value")
    if isinstance(value, dict):
        raise ReplayError(f"-p {name}:={text} is a mapping; a parameter's value is one value "
                          "or a [list]")
    return value


def parse_overrides(overrides) -> dict:
    values = {}
    for item in overrides or ():
        name, sep, text = item.partition(":=")
        if not sep or not name:
            raise ReplayError(f"-p expects NAME:=VALUE, got {item!r}")
        values[name] = parse_value(text, name)  # an empty text has no value there
    return values


def check_parameters(values: dict, where: dict) -> dict:
    """Check names, types, ranges and choices against fcop_node's declared parameters; return the
    values with integers given for double parameters made doubles. ``where`` names the source."""
    from ..ros.qos import qos_override_problem
    from ..ros.params import (PARAMETERS, ParameterError, allowed, check_value,
                              combination_conflict, defaults, did_you_mean, not_allowed)

    known = sorted(PARAMETERS)
    out = {}
    for name, value in values.items():
        src = where.get(name, "")
        if name in _ROS_PARAMETERS or name.startswith("qos_overrides."):
            # Checked here as the node would, before --out is touched (its refusal at start-up
            # came after the previous outputs were cleared).
            if name.startswith("qos_overrides."):
                problem = qos_override_problem(name.rsplit(".", 1)[-1], value)
            else:
                problem = "" if isinstance(value, bool) else "true or false"
            if problem:
                raise ReplayError(not_allowed(name, value, problem, src))
            out[name] = value
            continue
        if name not in PARAMETERS:
            raise ReplayError(
                f"unknown parameter {name!r} from {src}{did_you_mean(name)}; fcop_node's "
                f"parameters: {', '.join(known)}"
            )
        try:  # type, range, choices and what a descriptor cannot say, as the node checks them
            value = check_value(name, value)
        except ParameterError:
            raise ReplayError(not_allowed(name, value, allowed(name, value), src)) from None
        out[name] = value

    full = defaults()
    full.update({k: v for k, v in out.items() if k in PARAMETERS})
    # Blame the value moved from its default (a params file usually gives them all), and of two
    # moved, the one given by -p (the user's latest word).
    moved = {k for k, v in out.items() if k in PARAMETERS and v != PARAMETERS[k].default}
    name, rule = combination_conflict(
        full, changed={k for k in moved if where.get(k) == "-p"} or moved)
    if name:
        src = where.get(name, "the node's defaults")
        raise ReplayError(not_allowed(name, full[name], rule, src))
    return out


def node_parameters(params_file: str | None, overrides=()) -> dict:
    """The checked parameters the replayed node gets: the params file (default: the package's
    config/fcop.yaml), then the -p overrides."""
    path = params_file if params_file is not None else config_path()
    values = load_params_file(path)
    where = {k: f"--params-file {path}" for k in values}
    cli = parse_overrides(overrides)
    values.update(cli)
    where.update({k: "-p" for k in cli})
    return check_parameters(values, where)
