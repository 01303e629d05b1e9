"""Small helpers shared by the subcommands: argument parsers and output formatting."""

from __future__ import annotations

import argparse
import json
import sys
from typing import Any

import numpy as np

from ..exceptions import InvalidArgument
from ..schedule import Cycle

__all__ = ["parse_ts", "parse_pair", "parse_floats", "print_json", "fmt_table"]


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
