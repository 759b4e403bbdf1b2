"""The console scripts: each imports its tool only when run, with Ctrl-C and SIGTERM held
until the imports are done (1-2 s of numpy, numba and rclpy). Delivered in the middle of
them, Ctrl-C raised a traceback, or numpy turned it into an ImportError that blamed the
installation, or Python swallowed it and the node started anyway. A signal that came during
the imports ends the script as one after them does: exit 130 and one line for the tools, a
clean 0 for fcop_node. The tools take SIGTERM as Ctrl-C throughout (its default killed them
mid-write: a bag without its footer), so both close their outputs the same way."""
from __future__ import annotations

import importlib
import signal
import sys

from .tools.cli import from_ctrl_c

_HELD = {signal.SIGINT, signal.SIGTERM}


def _import_main(module: str):
    """``module``'s main, imported with _HELD blocked; (main, whether one of them came)."""
    before = signal.pthread_sigmask(signal.SIG_BLOCK, _HELD)
    try:
        main = importlib.import_module(module).main
    finally:
        came = signal.sigpending() & _HELD
        handlers = {s: signal.signal(s, signal.SIG_IGN) for s in came}  # discards them
        signal.pthread_sigmask(signal.SIG_SETMASK, before)
        for s, handler in handlers.items():
            signal.signal(s, handler)
    return main, bool(came)


def _as_ctrl_c(signum, frame):
    raise KeyboardInterrupt


def _quiet_half_built_logger(unraisable) -> None:
    """``sys.unraisablehook`` that leaves out one error: rclpy's RcutilsLogger sets its
    ``logger_sublogger_namepair`` after its name, and a Ctrl-C between the two makes its
    ``__del__`` print an AttributeError (nothing was registered, so nothing is lost). Every
    other unraisable error goes to the hook before it."""
    exc = unraisable.exc_value
    if isinstance(exc, AttributeError) and exc.name == "logger_sublogger_namepair":
        return
    _hook_before(unraisable)


_hook_before = sys.unraisablehook


def _run(module: str, prog: str, interrupted: int) -> int:
    sys.unraisablehook = _quiet_half_built_logger
    if interrupted:
        signal.signal(signal.SIGTERM, _as_ctrl_c)
    main, stopped = _import_main(module)
    try:
        if not stopped:
            return main()
    except KeyboardInterrupt:  # one that the tool's own handlers did not catch
        pass
    except Exception as exc:
        if not from_ctrl_c(exc):
            raise
    if interrupted:
        print(f"{prog}: interrupted", file=sys.stderr)
    return interrupted


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
