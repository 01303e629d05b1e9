"""Small helpers shared by the subcommands: argument parsers and output formatting."""

from __future__ import annotations

import argparse
import json
import re
import sys
from typing import Any

import numpy as np

from ..exceptions import InvalidArgument, ScheduleError
from ..model.schedule import Cycle

__all__ = ["parse_ts", "parse_pair", "parse_floats", "print_json", "fmt_table", "OneLineParser",
           "join_negative_values"]


def parse_floats(text: str, what: str) -> list[float]:
    try:
        return [float(x) for x in text.split(",") if x.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"{what} must be comma-separated numbers; got {text!r}") from None


def parse_ts(text: str) -> Cycle:
    """``TAU,S`` -> two-channel cycle (argparse type)."""
    vals = parse_floats(text, "--cycle")
    if len(vals) != 2:
        raise argparse.ArgumentTypeError(f"--cycle takes TAU,S (two numbers); got {text!r}")
    try:
        return Cycle.from_ts(*vals)
    except InvalidArgument as err:
        raise argparse.ArgumentTypeError(str(err)) from None


def parse_h(text: str) -> Cycle:
    """``H1,...,HN`` -> N-channel cycle (argparse type)."""
    try:
        return Cycle(parse_floats(text, "--cycle-h"))
    except InvalidArgument as err:
        raise argparse.ArgumentTypeError(str(err)) from None


def add_dead_time(p: argparse.ArgumentParser) -> None:
    """The ``--dead-time S`` flag (blind intervals after each switch, :mod:`switchobs_core.model.schedule`)."""
    p.add_argument("--dead-time", type=float, default=0.0, metavar="S",
                   help="seconds after each switch while the camera turns: only the rows every channel shares "
                        "(the camera's own pose) are measured (default 0)")


def with_dead_time(cycles: list[Cycle], dead_time: float) -> list[Cycle]:
    """``cycles`` with the ``--dead-time`` given (refused, in one line, when not >= 0 and finite
    or not shorter than every residence)."""
    if not dead_time:
        return list(cycles)
    try:
        return [c.with_dead_time(dead_time) for c in cycles]
    except ScheduleError as err:
        raise InvalidArgument(f"--dead-time {dead_time:g}: {err}") from None


def parse_pair(text: str) -> tuple[float, float]:
    vals = parse_floats(text, "value")
    if len(vals) != 2:
        raise argparse.ArgumentTypeError(f"expected two comma-separated numbers; got {text!r}")
    return vals[0], vals[1]


def _jsonable(obj: Any) -> Any:
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, (np.floating, np.integer)):
        return obj.item()
    if isinstance(obj, dict):
        return {k: _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_jsonable(v) for v in obj]
    return obj


def print_json(obj: Any) -> None:
    json.dump(_jsonable(obj), sys.stdout, indent=2)
    sys.stdout.write("\n")


def fmt_table(header: list[str], rows: list[list[Any]]) -> str:
    """Plain aligned text table."""
    cells = [[str(h) for h in header]] + [[str(c) for c in r] for r in rows]
    w = [max(len(r[j]) for r in cells) for j in range(len(header))]
    lines = ["  ".join(c.ljust(w[j]) for j, c in enumerate(r)).rstrip() for r in cells]
    lines.insert(1, "  ".join("-" * x for x in w))
    return "\n".join(lines)


_OPTION = re.compile(r"--[A-Za-z][\w-]*")
_NEGATIVE_VALUE = re.compile(r"-(\d|\.\d)")


def join_negative_values(argv: list[str]) -> list[str]:
    """``--cycle -2,0.6`` -> ``--cycle=-2,0.6``: argparse takes a value that starts with ``-`` for
    an option unless it is a plain negative number, so a comma list such as ``-2,0.6`` met
    "expected one argument" instead of the value's own check. (Our commands have no flag that
    is followed by a negative positional argument.)"""
    out: list[str] = []
    i = 0
    while i < len(argv):
        tok = argv[i]
        if _OPTION.fullmatch(tok) and i + 1 < len(argv) and _NEGATIVE_VALUE.match(argv[i + 1]):
            out.append(f"{tok}={argv[i + 1]}")
            i += 2
            continue
        out.append(tok)
        i += 1
    return out


class OneLineParser(argparse.ArgumentParser):
    """``argparse`` with the project's error convention: one line on stderr, ``PROG: error: ...``,
    exit code 2 (the usage is in ``--help``), and negative-looking values after an option."""

    def error(self, message: str):  # type: ignore[override]
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")

    def parse_known_args(self, args=None, namespace=None):  # type: ignore[override]
        args = join_negative_values(list(sys.argv[1:] if args is None else args))
        return super().parse_known_args(args, namespace)
