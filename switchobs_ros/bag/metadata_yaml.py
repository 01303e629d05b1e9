"""The YAML rosbags writes for a bag (each connection's offered QoS, ``metadata.yaml``), without ruamel's emitter.

rosbags' writer dumps each connection's QoS profiles and, when it closes, ``metadata.yaml`` twice
(the file, and the copy in the MCAP footer) with ``ruamel.yaml`` (``YAML(typ="safe")``, block style):
at 45 topics (``switchobs_bag estimate`` at 32 agents) about half a second of the command, whatever the
bag's length. :func:`block_yaml` writes the same text for the documents rosbags dumps, nested
mappings and sequences of strings, integers, booleans and None, in ruamel's layout (keys sorted, a
sequence's dash at its key's indentation, a plain scalar too long for the line's 80 columns moved to
the next line), and returns None for anything outside that subset (another type, an empty mapping or
sequence, a string that is not plainly an identifier-like name, a scalar in a sequence too long for its
line), which then goes to ruamel. The tests compare its text with ruamel's byte for byte.

:func:`install` gives rosbags' writer module a ``YAML`` whose ``dump`` uses :func:`block_yaml` for
the safe block-style dumps it makes and ruamel for everything else.
"""

from __future__ import annotations

import re
from typing import Any

__all__ = ["block_yaml", "install"]

#: ruamel's line width (``best_width``).
WIDTH = 80
#: Strings written plain: a name of letters, digits, ``_ / . -`` not starting with a digit, a dot or a dash.
_PLAIN = re.compile(r"[A-Za-z_/][A-Za-z0-9_/.\-]*\Z")
#: Plain-looking strings that YAML (1.1 or 1.2) reads as another type: ruamel quotes them.
_RESERVED = frozenset({"null", "true", "false", "yes", "no", "on", "off", "y", "n"})
#: Longest mapping key written here (a longer one: ruamel).
_KEY_MAX = 64


class _Unsupported(Exception):
    """Outside the subset: the caller uses ruamel."""


def _scalar(v: Any) -> str:
    if v is None:
        return "null"
    if v is True:
        return "true"
    if v is False:
        return "false"
    if type(v) is int:
        return str(v)
    if type(v) is str:
        if v == "":
            return "''"
        if _PLAIN.match(v) and v.lower() not in _RESERVED:
            return v
    raise _Unsupported


def _is_scalar(v: Any) -> bool:
    return not isinstance(v, (dict, list, tuple))


def _mapping(d: dict, indent: int, out: list[str], first: str | None = None) -> None:
    """``d`` at ``indent``; ``first``: the prefix of the first line (a sequence's ``- ``) instead of spaces."""
    if not d:
        raise _Unsupported
    pad = " " * indent
    for i, k in enumerate(sorted(d)):
        if type(k) is not str or len(k) > _KEY_MAX:
            raise _Unsupported
        key = _scalar(k)
        v = d[k]
        lead = first if i == 0 and first is not None else pad
        if _is_scalar(v):
            text = _scalar(v)
            column = indent + len(key) + 2
            if column + len(text) > WIDTH:     # ruamel: a word longer than the line gets a line of its own
                out.append(f"{lead}{key}: \n{pad}  {text}\n")
            else:
                out.append(f"{lead}{key}: {text}\n")
        elif isinstance(v, dict):
            out.append(f"{lead}{key}:\n")
            _mapping(v, indent + 2, out)
        else:
            out.append(f"{lead}{key}:\n")
            _sequence(v, indent, out)


def _sequence(seq: Any, indent: int, out: list[str]) -> None:
    if not isinstance(seq, (list, tuple)) or not seq:
        raise _Unsupported
    pad = " " * indent
    for item in seq:
        if isinstance(item, dict):
            _mapping(item, indent + 2, out, first=pad + "- ")
        elif _is_scalar(item):
            text = _scalar(item)
            if indent + 2 + len(text) > WIDTH:
                raise _Unsupported
            out.append(f"{pad}- {text}\n")
        else:
            raise _Unsupported


def block_yaml(data: Any) -> str | None:
    """What ``YAML(typ="safe")`` with ``default_flow_style = False`` dumps for ``data`` (a mapping or a
    sequence, module docstring), or None when ``data`` is outside the subset written here."""
    out: list[str] = []
    try:
        if isinstance(data, dict):
            _mapping(data, 0, out)
        else:
            _sequence(data, 0, out)
    except _Unsupported:
        return None
    return "".join(out)


class _SafeYAML:
    """``ruamel.yaml.YAML`` for rosbags' writer: :func:`block_yaml` where it applies, ruamel otherwise."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        from ruamel.yaml import YAML

        self._yaml = YAML(*args, **kwargs)
        self._safe = kwargs.get("typ", args[0] if args else None) == "safe"

    def __getattr__(self, name: str) -> Any:
        return getattr(self._yaml, name)

    def __setattr__(self, name: str, value: Any) -> None:
        if name in ("_yaml", "_safe"):
            object.__setattr__(self, name, value)
        else:
            setattr(self._yaml, name, value)

    def dump(self, data: Any, stream: Any = None, **kwargs: Any) -> Any:
        text = None
        if self._safe and not kwargs and stream is not None and self._yaml.default_flow_style is False:
            text = block_yaml(data)
        if text is None:
            return self._yaml.dump(data, stream, **kwargs)
        stream.write(text)
        return None


def install() -> None:
    """Give rosbags' writer module the ``YAML`` of :class:`_SafeYAML` (once; the same text)."""
    from rosbags.rosbag2 import writer

    if getattr(writer, "YAML", None) is not _SafeYAML:
        writer.YAML = _SafeYAML
