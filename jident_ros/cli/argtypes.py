"""argparse types shared by the ``jident`` subcommands: one line naming the flag and the value on a bad one."""
from __future__ import annotations

import argparse
import math


def finite_float_arg(name, positive=True, allow_zero=False):
    def parse(text):
        try:
            v = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{name} must be a number, got {text!r}") from None
        if not math.isfinite(v) or (positive and not (v > 0 or (allow_zero and v == 0))):
            raise argparse.ArgumentTypeError(f"{name} must be a finite number{' > 0' if positive else ''}, got {text}")
        return v
    return parse


def count_arg(name, minimum):
    def parse(text):
        try:
            v = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{name} must be an integer, got {text!r}") from None
        if v < minimum:
            raise argparse.ArgumentTypeError(f"{name} must be >= {minimum}, got {v}")
        return v
    return parse


def raising_parser(error_cls, prog: str, description: str):
    """An ArgumentParser whose usage errors raise ``error_cls(message)`` instead of exiting, so that the
    subcommand prints them as its own one-line error (``jident salvage``, ``jident samples``)."""

    class _Parser(argparse.ArgumentParser):
        def error(self, message):
            raise error_cls(message)

    return _Parser(prog=prog, description=description)
