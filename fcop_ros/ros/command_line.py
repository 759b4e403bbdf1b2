"""fcop_node's command line before rclpy sees it: ``--help`` (which rclpy ignores) and a
``--params-file`` checked so that a bad one gives one line and exit 2, not rcl's traceback."""
from __future__ import annotations

import re

import yaml

USAGE = """usage: fcop_node [-h] [--ros-args [-r FROM:=TO] [-p NAME:=VALUE]
                 [--params-file FILE] ...]

Estimates the camera's focal length from depth, NOCS and instance-mask images (topics depth,
nocs, mask; relative, remappable) and publishes CameraInfo, object poses, markers and
/diagnostics. Parameters, their defaults and ranges: config/fcop.yaml (installed as
share/fcop_ros/config/fcop.yaml) and the README's parameter table; at run time
`ros2 param describe <node> <name>`.

exit codes: 0 after a clean shutdown (Ctrl-C, SIGTERM); 2 for a parameter or params file it
cannot run with (one line on stderr)."""


def _ros_sections(args):
    """(index, argument, whether it stands inside a ``--ros-args`` ... ``--`` section) of each
    command-line argument but the section markers."""
    in_ros = False
    for i, arg in enumerate(args):
        if arg == "--ros-args":
            in_ros = True
        elif arg == "--":
            in_ros = False
        else:
            yield i, arg, in_ros


def wants_help(args) -> bool:
    """Whether ``-h`` or ``--help`` stands among the arguments outside ``--ros-args`` (rclpy
    ignores them; the node would start)."""
    return any(i > 0 and not in_ros and arg in ("-h", "--help")
               for i, arg, in_ros in _ros_sections(args))


def _names_parameters(doc) -> bool:
    """Whether a params file's YAML names parameters as rcl reads them: mappings of node names
    (under namespaces, or ``/**``) down to a ``ros__parameters`` mapping."""
    if not isinstance(doc, dict):
        return False
    return any(key == "ros__parameters" and isinstance(value, dict)
               or key != "ros__parameters" and _names_parameters(value)
               for key, value in doc.items())


def params_file_problem(args) -> str:
    """What is wrong with a ``--params-file`` among the ROS arguments ('' if nothing): a file
    that cannot be read, is not YAML, or names no ``ros__parameters``."""
    for i, arg, in_ros in _ros_sections(args):
        if in_ros and arg == "--params-file" and i + 1 < len(args):
            path = args[i + 1]
            try:
                with open(path, encoding="utf-8") as f:
                    docs = list(yaml.safe_load_all(f))  # rcl reads every document
            except OSError as exc:
                return f"cannot read params file {path}: {exc.strerror or exc}"
            except yaml.YAMLError as exc:
                return f"params file {path} is not YAML: {' '.join(str(exc).split())}"
            if not any(_names_parameters(doc) for doc in docs):
                return (f"params file {path} names no parameters: it wants "
                        "'<node name or /**>: ros__parameters: {name: value}' "
                        "(see config/fcop.yaml)")
    return ""


def rcl_params_error(exc) -> str:
    """rcl's words for ROS arguments it cannot parse (a params file, a -p value, a remap), without
    the source locations it appends."""
    text = re.sub(r", at [^,]+:[0-9]+", "", str(exc))
    return text.removeprefix("failed to initialize rcl: ")
