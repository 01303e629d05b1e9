"""Reading the files the tools take (system YAML, params YAML, gain-table JSON) with bounded
resources, and the value checks every file entry passes.

One owner for "a file a user hands us": every loader reads through :func:`read_text`
(size limit, UTF-8 only), parses YAML with :func:`parse_yaml` (no aliases or anchors, no
duplicate keys, nesting at most :data:`MAX_DEPTH`) and checks JSON nesting with
:func:`check_json_depth` before ``json.loads``. Numbers in a file pass :func:`file_number`
(finite, not a boolean, magnitude at most :data:`MAX_FILE_ENTRY`). Every refusal raises the
caller's error class with one line naming the file and the place in it.

Why: a 1 KB YAML alias bomb expands to gigabytes (50 s, 2.5 GB, then ``MemoryError``);
``[[[[...]]]]`` nested 100 000 deep ends in ``RecursionError``; binary garbage in
``UnicodeDecodeError``; ``true`` is a number to numpy.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

__all__ = ["MAX_FILE_BYTES", "MAX_DEPTH", "MAX_FILE_ENTRY", "read_text", "parse_yaml", "check_json_depth",
           "file_number", "check_file_matrix"]

#: Largest file a tool reads (16 MiB; the largest gain table we write is a few MB).
MAX_FILE_BYTES = 16 * 2**20
#: Deepest nesting of lists/mappings in a file (a system file needs 4, a gain table about 8).
MAX_DEPTH = 64
#: Largest magnitude of a number in a system file: beyond it products overflow long before a
#: design could mean anything (an entry of 1e300 made the SDP solver fail on allocation).
MAX_FILE_ENTRY = 1e12


def read_text(path: str | Path, what: str, error: type[Exception]) -> str:
    """The text of ``path`` (UTF-8, at most :data:`MAX_FILE_BYTES`), or ``error`` with one line."""
    path = Path(path)
    try:
        with path.open("rb") as fh:
            data = fh.read(MAX_FILE_BYTES + 1)
    except OSError as err:
        raise error(f"cannot read {what} {path}: {err.strerror or err}") from None
    if len(data) > MAX_FILE_BYTES:
        raise error(f"{what} {path} is larger than {MAX_FILE_BYTES // 2**20} MiB: not a file this tool reads")
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as err:
        raise error(f"{what} {path} is not UTF-8 text (byte 0x{data[err.start]:02x} at offset {err.start}): "
                    "is it the right file?") from None


_NO_ALIAS = "YAML anchors and aliases (&name, *name) are not accepted: write the values out"


def _safe_loader():
    """A ``yaml.SafeLoader`` that refuses aliases/anchors and duplicate keys, with a depth limit."""
    import yaml

    class _Loader(yaml.SafeLoader):
        depth = 0

        def compose_node(self, parent, index):
            if self.check_event(yaml.AliasEvent):
                ev = self.peek_event()
                raise yaml.composer.ComposerError(None, None, _NO_ALIAS,
                                                  ev.start_mark)
            ev = self.peek_event()
            if getattr(ev, "anchor", None) is not None:
                raise yaml.composer.ComposerError(None, None, _NO_ALIAS, ev.start_mark)
            self.depth += 1
            if self.depth > MAX_DEPTH:
                raise yaml.composer.ComposerError(None, None, f"nested deeper than {MAX_DEPTH} levels",
                                                  ev.start_mark)
            try:
                return super().compose_node(parent, index)
            finally:
                self.depth -= 1

        def construct_mapping(self, node, deep=False):
            seen = set()
            for key_node, _ in node.value:
                key = self.construct_object(key_node, deep=True)
                try:
                    dup = key in seen
                except TypeError:       # an unhashable key: let the base class say so
                    break
                if dup:
                    raise yaml.constructor.ConstructorError(None, None, f"duplicate key {key!r}",
                                                            key_node.start_mark)
                seen.add(key)
            return super().construct_mapping(node, deep=deep)

    return _Loader


def parse_yaml(text: str, where: str, error: type[Exception]) -> Any:
    """Parse YAML text safely (module docstring); ``where`` names the file in the message."""
    import yaml

    try:
        return yaml.load(text, Loader=_safe_loader())   # a SafeLoader subclass
    except yaml.YAMLError as err:
        mark = getattr(err, "problem_mark", None)
        at = f" at line {mark.line + 1}, column {mark.column + 1}" if mark is not None else ""
        problem = getattr(err, "problem", None) or str(err).splitlines()[0]
        raise error(f"{where}: not valid YAML{at}: {problem}") from None
    except RecursionError:      # not reached with MAX_DEPTH; kept as the last line of defence
        raise error(f"{where}: nested too deeply") from None


def check_json_depth(text: str, where: str, error: type[Exception]) -> None:
    """Refuse JSON nested deeper than :data:`MAX_DEPTH` before ``json.loads`` recurses into it
    (one pass over the text, strings skipped)."""
    depth, in_str, esc = 0, False, False
    for i, ch in enumerate(text):
        if in_str:
            if esc:
                esc = False
            elif ch == "\\":
                esc = True
            elif ch == '"':
                in_str = False
        elif ch == '"':
            in_str = True
        elif ch in "[{":
            depth += 1
            if depth > MAX_DEPTH:
                raise error(f"{where}: nested deeper than {MAX_DEPTH} levels (character {i}): not a file this "
                            "tool wrote")
        elif ch in "]}":
            depth -= 1


def file_number(v: Any, where: str, error: type[Exception], limit: float = MAX_FILE_ENTRY) -> float:
    """``v`` as a float if it is a finite number of magnitude <= ``limit`` (booleans are not)."""
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise error(f"{where} must be a number; got {v!r}")
    f = float(v)
    if not (math.isfinite(f) and abs(f) <= limit):
        raise error(f"{where} must be a finite number of magnitude <= {limit:g}; got {v!r}")
    return f


def check_file_matrix(M: Any, where: str, error: type[Exception], limit: float = MAX_FILE_ENTRY) -> None:
    """Every entry of a (nested list) matrix from a file passes :func:`file_number`."""
    rows = M if isinstance(M, list) else [M]
    for i, row in enumerate(rows):
        for j, v in enumerate(row if isinstance(row, list) else [row]):
            if isinstance(v, list):
                raise error(f"{where}[{i}][{j}] must be a number; got a list")
            file_number(v, f"{where}[{i}][{j}]", error, limit)
