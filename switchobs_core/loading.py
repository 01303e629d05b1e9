"""Bounded loading of the files the tools read: system and params YAML, gain-table JSON.

Every file goes through this module, which refuses a bad file with the caller's error class
(a :class:`~switchobs_core.exceptions.SwitchobsError`) and a one-line message naming the file
and, where it can, the place in it (line, key path) in the file's own words. The limits:

* kind: a regular file only (:mod:`switchobs_core.files`: a FIFO, a device or a directory is
  refused before it is read);
* size: at most :data:`MAX_FILE_BYTES` (16 MiB) for a gain table, :data:`MAX_YAML_BYTES`
  (1 MiB) for a YAML file (hand-written; a 1 MiB YAML file holds a dense ~300 x 300 matrix).
  Only the limit plus one byte is ever read, so ``/dev/zero`` is refused, not read forever;
* text: UTF-8 only (the message gives the line and column of the first bad byte);
* YAML: no anchors (``&name``) and no aliases (``*name``) (a 1 KB "billion laughs" file
  would otherwise expand to gigabytes), no duplicate mapping keys, at most
  :data:`MAX_DEPTH` nested lists/mappings; parsed with libyaml when available;
* JSON: ``NaN``/``Infinity`` refused, at most :data:`MAX_DEPTH` nested arrays/objects (checked
  without recursion);
* numbers (:func:`as_number`, :func:`number_matrix`): booleans are not numbers; strings holding
  a number are (PyYAML reads ``1e-3`` without a dot as a string); finite; system matrix entries
  at most :data:`~switchobs_core.validation.MAX_ABS_SYSTEM_ENTRY` (1e12) in magnitude.
"""

from __future__ import annotations

import json
import math
import re
from pathlib import Path
from typing import Any

import numpy as np

from .exceptions import SwitchobsError
from .files import open_input
from .validation import MAX_ABS_SYSTEM_ENTRY

__all__ = [
    "MAX_FILE_BYTES",
    "MAX_YAML_BYTES",
    "MAX_DEPTH",
    "read_text",
    "parse_yaml",
    "load_yaml",
    "parse_json",
    "check_depth",
    "json_depth",
    "as_number",
    "number_matrix",
]

#: Largest file read (gain tables): 16 MiB.
MAX_FILE_BYTES = 16 * 1024 * 1024
#: Largest YAML file read (system and params files): 1 MiB.
MAX_YAML_BYTES = 1024 * 1024
#: Deepest nesting of lists/mappings (arrays/objects) in any file; the deepest real file
#: (a Kalman gain table) nests 6 levels.
MAX_DEPTH = 32


def _mib(n: int) -> str:
    return f"{n / 1024 / 1024:g} MiB"


def read_text(path: str | Path, *, exc: type[SwitchobsError], what: str,
              max_bytes: int = MAX_FILE_BYTES) -> str:
    """The UTF-8 text of ``path``, at most ``max_bytes`` long; else ``exc`` naming ``what path``.

    A missing file raises ``FileNotFoundError`` (callers word that themselves); every other
    problem raises ``exc``.
    """
    path = Path(path)
    try:
        with open_input(path, what, exc=exc, max_bytes=max_bytes) as fh:   # regular files only
            data = fh.read(max_bytes + 1)
    except FileNotFoundError:
        raise
    except OSError as err:
        raise exc(f"cannot read {what} {path}: {err.strerror or err}") from None
    if len(data) > max_bytes:
        raise exc(f"{what} {path} is larger than {_mib(max_bytes)} (the limit for this kind of file)")
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as err:
        line = data.count(b"\n", 0, err.start) + 1
        col = err.start - (data.rfind(b"\n", 0, err.start) + 1) + 1
        raise exc(f"{what} {path} is not UTF-8 text (byte 0x{data[err.start]:02x} at line {line}, "
                  f"column {col}): is it a binary file?") from None


# ----------------------------------------------------------------------------- YAML


class _Refused(Exception):
    """Raised inside the YAML loader; turned into the caller's error class."""


def _make_loader() -> type:
    import yaml
    from yaml.composer import Composer
    from yaml.constructor import SafeConstructor
    from yaml.resolver import Resolver

    try:
        from yaml._yaml import CParser as Parser  # libyaml: C scanner and parser
        from_c = True
    except ImportError:  # pragma: no cover - PyYAML without libyaml
        from yaml.parser import Parser
        from yaml.reader import Reader
        from yaml.scanner import Scanner
        from_c = False

    class StrictComposer(Composer):
        """Composer (the pure-Python one, on top of either parser) that refuses anchors,
        aliases and nesting deeper than MAX_DEPTH before it recurses."""

        def compose_node(self, parent: Any, index: Any) -> Any:
            event = self.peek_event()
            line = event.start_mark.line + 1 if event.start_mark is not None else "?"
            if isinstance(event, yaml.AliasEvent):
                raise _Refused(f"line {line}: YAML aliases (*{event.anchor}) are not allowed")
            if getattr(event, "anchor", None) is not None:
                raise _Refused(f"line {line}: YAML anchors (&{event.anchor}) are not allowed")
            if isinstance(event, (yaml.SequenceStartEvent, yaml.MappingStartEvent)):
                self._depth = getattr(self, "_depth", 0) + 1
                try:
                    if self._depth > MAX_DEPTH:
                        raise _Refused(f"line {line}: lists/mappings nested deeper than {MAX_DEPTH} levels")
                    return super().compose_node(parent, index)
                finally:
                    self._depth -= 1
            return super().compose_node(parent, index)

    class StrictConstructor(SafeConstructor):
        def construct_mapping(self, node: Any, deep: bool = False) -> Any:
            if isinstance(node, yaml.MappingNode):
                seen: set = set()
                for key_node, _ in node.value:
                    if key_node.tag == "tag:yaml.org,2002:merge":
                        raise _Refused(f"line {key_node.start_mark.line + 1}: YAML merge keys (<<) are not allowed")
                    key = self.construct_object(key_node, deep=True)
                    try:
                        dup = key in seen
                        seen.add(key)
                    except TypeError:
                        raise _Refused(f"line {key_node.start_mark.line + 1}: a mapping key must be a "
                                       "plain value, not a list or mapping") from None
                    if dup:
                        raise _Refused(f"line {key_node.start_mark.line + 1}: duplicate key {key!r}")
            return super().construct_mapping(node, deep=deep)

    if from_c:
        class Loader(Parser, StrictComposer, StrictConstructor, Resolver):
            def __init__(self, stream: str) -> None:
                Parser.__init__(self, stream)
                StrictComposer.__init__(self)
                StrictConstructor.__init__(self)
                Resolver.__init__(self)

            # CParser has its own (C) composer; use the strict Python one on its events
            get_single_node = StrictComposer.get_single_node
            get_node = StrictComposer.get_node
            check_node = StrictComposer.check_node
            compose_document = StrictComposer.compose_document
            compose_node = StrictComposer.compose_node
    else:  # pragma: no cover
        class Loader(Reader, Scanner, Parser, StrictComposer, StrictConstructor, Resolver):
            def __init__(self, stream: str) -> None:
                Reader.__init__(self, stream)
                Scanner.__init__(self)
                Parser.__init__(self)
                StrictComposer.__init__(self)
                StrictConstructor.__init__(self)
                Resolver.__init__(self)

    return Loader


_LOADER: type | None = None


def parse_yaml(text: str, *, exc: type[SwitchobsError], source: str) -> Any:
    """Parse one YAML document with the strict loader (module docstring); ``exc`` names ``source``."""
    import yaml

    global _LOADER
    if _LOADER is None:
        _LOADER = _make_loader()
    loader = _LOADER(text)
    try:
        return loader.get_single_data()
    except _Refused as err:
        raise exc(f"{source}: {err}") from None
    except yaml.MarkedYAMLError as err:
        mark = err.problem_mark or err.context_mark
        where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark is not None else ""
        raise exc(f"{source}: not valid YAML{where}: {' '.join(str(err.problem or err.context).split())}") from None
    except yaml.reader.ReaderError as err:  # a character YAML does not allow (e.g. NUL)
        ch = f"#x{err.character:04x}" if isinstance(err.character, int) else repr(err.character)
        raise exc(f"{source}: not valid YAML: character {ch} at position {err.position} is not allowed in YAML "
                  "(a binary file?)") from None
    except yaml.YAMLError as err:
        raise exc(f"{source}: not valid YAML: {' '.join(str(err).split())}") from None
    except (ValueError, OverflowError, RecursionError) as err:  # e.g. an integer of 5000 digits
        raise exc(f"{source}: unreadable YAML value ({' '.join(str(err).split())[:200]})") from None
    finally:
        loader.dispose()


def load_yaml(path: str | Path, *, exc: type[SwitchobsError], what: str,
              max_bytes: int = MAX_YAML_BYTES) -> Any:
    """Read (:func:`read_text`) and parse (:func:`parse_yaml`) a YAML file."""
    text = read_text(path, exc=exc, what=what, max_bytes=max_bytes)
    return parse_yaml(text, exc=exc, source=f"{what} {path}")


# ----------------------------------------------------------------------------- JSON


def parse_json(text: str, *, exc: type[SwitchobsError], source: str) -> Any:
    """Parse JSON: ``NaN``/``Infinity`` and nesting deeper than :data:`MAX_DEPTH` refused.

    A ``json.JSONDecodeError`` is left to the caller (which knows what a truncated file means).
    """

    def _constant(name: str) -> float:
        raise exc(f"{source}: contains a non-finite number ({name})")

    try:
        data = json.loads(text, parse_constant=_constant)
    except RecursionError:  # the C decoder stops itself at the interpreter's recursion limit
        raise exc(f"{source}: arrays/objects nested deeper than {MAX_DEPTH} levels") from None
    if json_depth(text) > MAX_DEPTH:
        raise exc(f"{source}: arrays/objects nested deeper than {MAX_DEPTH} levels")
    return data


#: A JSON string literal (RFC 8259: no raw quote or backslash inside but escaped ones).
_JSON_STRING = re.compile(r'"(?:[^"\\]|\\.)*"')
#: Every byte but the four brackets, deleted by :func:`json_depth`.
_NOT_BRACKET = bytes(c for c in range(256) if c not in b"[]{}")
#: +1 for an opening bracket, -1 for a closing one, by byte.
_BRACKET_STEP = np.zeros(256, dtype=np.int64)
_BRACKET_STEP[list(b"[{")] = 1
_BRACKET_STEP[list(b"]}")] = -1


def json_depth(text: str) -> int:
    """How deep arrays/objects nest in ``text``, JSON that parses (the top level's array or object is
    level 1; a number or string alone is 0): the largest count of open brackets outside string
    literals, what :func:`check_depth` finds walking the parsed value (tested against it), at the
    cost of a regular expression and a few numpy calls instead of a visit of every member. Text without
    a backslash has no escaped quote, so every quote opens or closes a literal: the text between
    literals is every other piece of a split at the quotes (a tenth of the expression's time on a
    table's header)."""
    if "\\" in text:
        outside = _JSON_STRING.sub("", text)
    else:
        outside = "".join(text.split('"')[::2])
    brackets = outside.encode("utf-8").translate(None, _NOT_BRACKET)
    steps = _BRACKET_STEP[np.frombuffer(brackets, dtype=np.uint8)]
    return int(np.cumsum(steps).max(initial=0))


def check_depth(obj: Any, *, exc: type[SwitchobsError], source: str, limit: int = MAX_DEPTH) -> None:
    """Raise ``exc`` if lists/dicts in ``obj`` nest deeper than ``limit`` (iterative walk)."""
    stack = [(obj, 1)]
    while stack:
        node, depth = stack.pop()
        if isinstance(node, (list, tuple, dict)):
            if depth > limit:
                raise exc(f"{source}: arrays/objects nested deeper than {limit} levels")
            children = node.values() if isinstance(node, dict) else node
            stack.extend((c, depth + 1) for c in children if isinstance(c, (list, tuple, dict)))


# ----------------------------------------------------------------------------- values


def as_number(x: Any, where: str, *, exc: type[SwitchobsError], finite: bool = True,
              max_abs: float | None = None) -> float:
    """``x`` as a float: ints, floats and strings holding a number (PyYAML reads ``1e-3`` as a
    string); booleans refused; finite (with ``finite``); ``|x| <= max_abs`` when given."""
    if isinstance(x, (bool, np.bool_)):
        raise exc(f"{where} must be a number; got the boolean {str(x).lower()}")
    if isinstance(x, str):
        try:
            val = float(x)
        except ValueError:
            raise exc(f"{where} must be a number; got the string {x[:40]!r}") from None
    elif isinstance(x, (int, float, np.integer, np.floating)):
        try:
            val = float(x)
        except OverflowError:
            raise exc(f"{where}: the integer {str(x)[:20]}... is too large") from None
    else:
        raise exc(f"{where} must be a number; got {_kind(x)}")
    if finite and not math.isfinite(val):
        raise exc(f"{where} must be a finite number; got {val}")
    if max_abs is not None and abs(val) > max_abs:
        raise exc(f"{where} = {val:.3g} is beyond the supported magnitude {max_abs:g}")
    return val


def _kind(x: Any) -> str:
    if x is None:
        return "nothing (null)"
    if isinstance(x, dict):
        return "a mapping"
    if isinstance(x, (list, tuple)):
        return "a list"
    return f"{type(x).__name__} {str(x)[:40]!r}"


def number_matrix(x: Any, where: str, *, exc: type[SwitchobsError],
                  max_abs: float | None = MAX_ABS_SYSTEM_ENTRY) -> Any:
    """Check a matrix read from a file: a list of rows (or one row) of numbers
    (:func:`as_number`, so no booleans, finite, ``|entry| <= max_abs``); returns it as nested
    lists of floats (the shape is checked by :func:`~switchobs_core.validation.as_matrix`)."""
    if isinstance(x, (dict, type(None))):
        raise exc(f"{where} must be a matrix (a list of rows of numbers); got {_kind(x)}")
    if not isinstance(x, (list, tuple)):
        return as_number(x, where, exc=exc, max_abs=max_abs)   # as_matrix refuses the shape
    out = []
    for i, row in enumerate(x):
        if isinstance(row, (list, tuple)):
            out.append([_entry(v, f"{where} row {i + 1}, column {j + 1}", exc, max_abs) for j, v in enumerate(row)])
        else:
            out.append(_entry(row, f"{where} entry {i + 1}", exc, max_abs))
    return out


def _entry(v: Any, where: str, exc: type[SwitchobsError], max_abs: float | None) -> float:
    if isinstance(v, (list, tuple, dict)):
        raise exc(f"{where} must be a number; got {_kind(v)} (a matrix is a list of rows of numbers)")
    return as_number(v, where, exc=exc, max_abs=max_abs)

