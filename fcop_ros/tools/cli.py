"""What the command-line tools share: a help format that shows every default."""
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
