"""Number lists in the ROS arguments: ``[1, 0.8, 0.8]`` is a list of doubles.

rcl reads a YAML list as one type and refuses one that mixes integers and decimals (``Sequence
should be of same type``), in a params file (``schedule: {h: [1, 0.8, 0.8]}``) and in ``-p
schedule.h:=[1, 0.8, 0.8]``. Every list parameter of the nodes whose items are numbers is a list
of doubles, so :func:`with_float_lists` writes such a list's integers as decimals before rcl reads
the arguments: a params file that mixes them is read from a corrected copy (a temporary file,
removed at exit), a ``-p`` value is rewritten in place. Anything else is left to rcl.
"""

from __future__ import annotations

import atexit
import os
import re
import tempfile
from collections.abc import Sequence
from typing import Any

import yaml

__all__ = ["with_float_lists"]

_FLOW = re.compile(r"\[[^\[\]\n#]*\]")      # a one-line flow list without nested lists or comments


def _mixed(v: Any) -> bool:
    """A list of numbers, some integers and some not."""
    if not isinstance(v, list) or not v or not all(isinstance(x, (int, float)) and not isinstance(x, bool)
                                                   for x in v):
        return False
    return any(isinstance(x, int) for x in v) and any(isinstance(x, float) for x in v)


def _floats(text: str) -> str | None:
    """``[1.0, 0.8, 0.8]`` for the YAML flow list ``text`` if it mixes integers and decimals, else None."""
    try:
        v = yaml.safe_load(text)
    except yaml.YAMLError:
        return None
    return f"[{', '.join(repr(float(x)) for x in v)}]" if _mixed(v) else None


def _fixed_file(path: str) -> str | None:
    """A corrected copy of the params file at ``path`` (None: nothing to correct, or not readable). Only
    the flow lists (``[...]``) that mix integers and decimals change; the rest of the text is kept as
    is (rcl's YAML is not PyYAML's: ``1.0e6`` is a double there, a string here)."""
    try:
        with open(path) as fh:
            text = fh.read()
    except (OSError, UnicodeDecodeError):
        return None       # rcl says what is wrong with it
    fixed = _FLOW.sub(lambda m: _floats(m.group(0)) or m.group(0), text)
    if fixed == text:
        return None
    fd, tmp = tempfile.mkstemp(prefix="switchobs-params-", suffix=".yaml")
    with os.fdopen(fd, "w") as fh:
        fh.write(fixed)
    atexit.register(lambda: os.path.exists(tmp) and os.unlink(tmp))
    return tmp


def _fixed_value(assign: str) -> str:
    """A ``name:=value`` whose value is a mixed number list, with the value as floats."""
    name, sep, value = assign.partition(":=")
    if not sep:
        return assign
    fixed = _floats(value) if value.lstrip().startswith("[") else None
    return f"{name}:={fixed}" if fixed else assign


def with_float_lists(argv: Sequence[str]) -> list[str]:
    """``argv`` with mixed integer/decimal number lists of ``--params-file`` files and ``-p`` values
    made decimals (module docstring)."""
    out = list(argv)
    in_ros = False
    for i, a in enumerate(out):
        if a == "--ros-args":
            in_ros = True
        elif a == "--":
            in_ros = False
        elif in_ros and i > 0 and out[i - 1] == "--params-file":
            out[i] = _fixed_file(a) or a
        elif in_ros and i > 0 and out[i - 1] in ("-p", "--param"):
            out[i] = _fixed_value(a)
    return out
