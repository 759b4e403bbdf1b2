"""What the command-line tools share: a help format that shows every default, and how to tell
an error that Ctrl-C caused."""
from __future__ import annotations

import argparse


class HelpFormatter(argparse.ArgumentDefaultsHelpFormatter, argparse.RawDescriptionHelpFormatter):
    """Shows '(default: X)' for every option that has a default (not for required ones, flags,
    whose default is their absence, or those whose absence the help text explains), and keeps
    the description and epilog as written."""

    def _get_help_string(self, action):
        flag = isinstance(action, (argparse._StoreTrueAction, argparse._StoreFalseAction))
        empty = isinstance(action.default, (list, tuple)) and not action.default  # -p ...
        if action.default is None or action.required or flag or empty:
            return action.help
        return super()._get_help_string(action)


def from_ctrl_c(exc: BaseException) -> bool:
    """Whether ``exc`` is, or was raised while handling, a KeyboardInterrupt: Ctrl-C can
    surface as another error (numba's SystemError around a compiled kernel, a RuntimeError
    from a dataclass interrupted while a lazy import built it)."""
    seen = set()
    while exc is not None and id(exc) not in seen:
        if isinstance(exc, KeyboardInterrupt):
            return True
        seen.add(id(exc))
        exc = exc.__cause__ or exc.__context__
    return False


def raise_ctrl_c(exc: BaseException) -> None:
    """Raise KeyboardInterrupt, from ``exc``, where ``exc`` came of Ctrl-C (:func:`from_ctrl_c`):
    a handler that takes any error for a damaged bag must not take an interrupted read for one
    (Ctrl-C inside rclpy's deserialisation surfaces as pybind11's TypeError or RuntimeError,
    "Unable to convert ...", and a replay said "bag damaged")."""
    if from_ctrl_c(exc):
        raise KeyboardInterrupt from exc
