"""The console scripts: each imports its tool only when run, so that Ctrl-C during those
imports (1-2 s of numpy, numba and rclpy) ends it as Ctrl-C later does, without a traceback:
exit 130 for the tools, 0 for fcop_node (a clean shutdown, as ROS nodes exit)."""
from __future__ import annotations

import importlib
import sys


def _run(module: str, prog: str, interrupted: int) -> int:
    try:
        main = importlib.import_module(module).main
    except KeyboardInterrupt:
        if interrupted:
            print(f"{prog}: interrupted", file=sys.stderr)
        return interrupted
    return main()


def fcop_node() -> int:
    return _run("fcop_ros.ros.node", "fcop_node", 0)


def fcop_demo() -> int:
    return _run("fcop_ros.tools.demo", "fcop_demo", 130)


def fcop_replay() -> int:
    return _run("fcop_ros.tools.replay", "fcop_replay", 130)


def fcop_make_bag() -> int:
    return _run("fcop_ros.tools.make_bag", "fcop_make_bag", 130)


def fcop_eval_nocs() -> int:
    return _run("fcop_ros.tools.nocs_eval", "fcop_eval_nocs", 130)
