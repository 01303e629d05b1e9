"""The gain table's file: JSON or the binary container, written atomically, read with every check.

The format is described in :mod:`switchobs_core.table.gains`. Floats are written with Python's shortest round-trip
repr, so a table round-trips bit for bit. The file is written atomically (temporary file in the
same folder, fsync, rename). Loading checks the format and version, the checksum, that every
number is finite, the layout (:mod:`switchobs_core.table.schema`), and (given a system) the system fingerprint
and that the stored observable bases T_o are the system's. :class:`~switchobs_core.table.gains.GainTable`'s
``save``, ``load``, ``to_json`` and ``from_json`` call these functions.
"""

from __future__ import annotations

import hashlib
import json
import os
import secrets
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any, BinaryIO

from ..exceptions import GainTableError
from ..families import TABLE_FAMILIES
from ..files import check_output
from ..loading import MAX_FILE_BYTES, parse_json, read_text
from .container import decode, encode, is_binary, jsonable
from .lmi import CycleDesign
from .schema import check_finite, check_layout

if TYPE_CHECKING:
    from ..model.system import LTISystem

__all__ = ["FORMAT", "FORMAT_VERSION", "READABLE_VERSIONS"]

FORMAT = "switchobs-gain-table"
FORMAT_VERSION = 2
#: Versions this software reads (1: LMI tables from before the Kalman family).
READABLE_VERSIONS = (1, 2)


def table_payload(table: Any) -> dict[str, Any]:
    return {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "software_version": table.software_version,
        "system": {
            "name": table.system_name,
            "fingerprint": table.fingerprint,
            "n": table.n,
            "p": list(table.p),
            "N": table.N,
        },
        "delta": list(table.delta),
        "settings": table.settings,
        "channels": table.channels,
        "designs": [d.to_dict() for d in table.designs],
        "robust": None if table.robust is None else table.robust.to_dict(),
        "family": table.family,
        "kalman": table.kalman,
    }


def digest(payload: dict[str, Any]) -> str:
    text = json.dumps(payload, sort_keys=True, allow_nan=True, default=jsonable)
    return hashlib.sha256(text.encode()).hexdigest()


def to_json(table: Any) -> str:
    """The file's text."""
    payload = table_payload(table)
    check_finite(payload, "gain table")
    payload["payload_sha256"] = digest(payload)
    return json.dumps(payload, indent=1, sort_keys=True, allow_nan=False, default=jsonable) + "\n"


def writer(table: Any, *, binary: bool = False) -> Callable[[BinaryIO], Any]:
    """What writes the file to a binary handle: the JSON text, or (``binary``) the ``.npz``
    container of :mod:`switchobs_core.table.container` (streamed: no copy of the file in memory)."""
    if not binary:
        text = to_json(table).encode()
        return lambda fh: fh.write(text)
    payload = table_payload(table)
    check_finite(payload, "gain table")
    return lambda fh: encode(payload, fh)


def save(table: Any, path: str | Path) -> Path:
    """Write the table atomically (temporary file, fsync, rename): JSON, or the binary
    container of :mod:`switchobs_core.table.container` when the name ends in ``.npz``.

    The file gets the mode a plain ``open(path, "w")`` would give (0666 less the umask,
    usually 0644), so a service running as another user can read it; ``tempfile`` would
    make it 0600."""
    path = check_output(path, "gain table", exc=GainTableError)   # never replace a directory or device
    return _write_atomic(path, writer(table, binary=path.suffix.lower() == ".npz"))


#: Fewest bytes a float takes in the JSON text (a short repr, its indent, the comma and newline).
MIN_JSON_FLOAT_BYTES = 8


def _floats(obj: Any) -> int:
    """How many numbers a payload holds (arrays, lists, mappings walked; nothing serialised)."""
    if isinstance(obj, (str, bytes)) or obj is None:
        return 0
    if isinstance(obj, (int, float)):
        return 1
    if isinstance(obj, dict):
        return sum(_floats(v) for v in obj.values())
    if isinstance(obj, (list, tuple)):
        return sum(_floats(v) for v in obj)
    size = getattr(obj, "size", None)
    if isinstance(size, int):
        return size
    if hasattr(obj, "__len__") and hasattr(obj, "__getitem__"):
        return sum(_floats(v) for v in obj)
    to_dict = getattr(obj, "to_dict", None)
    return _floats(to_dict()) if callable(to_dict) else 0


def save_loadable(table: Any, path: str | Path) -> tuple[Path, int | None]:
    """Save ``table`` at ``path``, or, when ``path`` is a JSON name and the JSON would exceed
    :data:`~switchobs_core.loading.MAX_FILE_BYTES` (the largest JSON table that loading reads), as the
    binary container beside it (``path`` with ``.npz``), which loading reads at any size this
    software designs. Returns ``(the path written, the JSON's size in bytes when it was too large,
    else None)``; the size is a lower bound when the JSON was not formed (about 17 bytes a float in
    practice, at least :data:`MIN_JSON_FLOAT_BYTES`)."""
    path = check_output(path, "gain table", exc=GainTableError)
    if path.suffix.lower() == ".npz":
        return _write_atomic(path, writer(table, binary=True)), None
    payload = table_payload(table)
    size = _floats(payload) * MIN_JSON_FLOAT_BYTES
    if size <= MAX_FILE_BYTES:           # small enough to form: its real size decides
        text = to_json(table).encode()
        if len(text) <= MAX_FILE_BYTES:
            return _write_atomic(path, lambda fh: fh.write(text)), None
        size = len(text)
    npz = check_output(path.with_suffix(".npz"), "gain table", exc=GainTableError)
    return _write_atomic(npz, writer(table, binary=True)), size


def _write_atomic(path: Path, write: Callable[[BinaryIO], Any]) -> Path:
    """``write(fh)`` into a temporary file beside ``path``, fsync, rename (:func:`save`)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    while True:
        tmp = path.parent / f".{path.name}.{secrets.token_hex(6)}.tmp"
        try:
            fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)
            break
        except FileExistsError:  # pragma: no cover - 48 random bits
            continue
    try:
        with os.fdopen(fd, "wb") as fh:
            write(fh)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return path


def from_json(cls: Any, text: str, *, source: str = "<text>", system: LTISystem | None = None) -> Any:
    """Parse and check a table (see module docstring); ``system`` adds the fingerprint check."""

    try:
        data = parse_json(text, exc=GainTableError, source=source)
    except json.JSONDecodeError as err:
        raise GainTableError(
            f"{source}: not a complete gain table (JSON error at line {err.lineno}: {err.msg}); "
            "the file may be truncated: design it again"
        ) from None
    if not isinstance(data, dict) or data.get("format") != FORMAT:
        raise GainTableError(f"{source}: not a switchobs gain table (format field missing or wrong)")
    version = data.get("format_version")
    if isinstance(version, bool) or version not in READABLE_VERSIONS:
        raise GainTableError(
            f"{source}: gain table format version {version!r} "
            f"is not supported (this software reads versions {', '.join(map(str, READABLE_VERSIONS))})"
        )
    if "payload_sha256" not in data:
        raise GainTableError(f"{source}: the checksum (payload_sha256) is missing: the file was not written by "
                             "switchobs or was edited; design it again")
    stored = data.pop("payload_sha256")
    check_finite(data, source)
    if stored != digest(data):
        raise GainTableError(
            f"{source}: checksum mismatch: the file was modified or corrupted after it was written"
        )
    return from_payload(cls, data, source=source, system=system)


def from_payload(cls: Any, data: dict[str, Any], *, source: str, system: LTISystem | None) -> Any:
    """The table of a checked payload (format, version and checksum already checked)."""
    check_layout(data, source)
    try:
        sysd = data["system"]
        table = cls(
            system_name=str(sysd["name"]),
            fingerprint=str(sysd["fingerprint"]),
            n=int(sysd["n"]),
            p=tuple(int(x) for x in sysd["p"]),
            delta=tuple(float(x) for x in data["delta"]),
            settings=dict(data["settings"]),
            channels=list(data["channels"]),
            designs=[CycleDesign.from_dict(d) for d in data["designs"]],
            robust=None if data["robust"] is None else CycleDesign.from_dict(data["robust"]),
            software_version=str(data["software_version"]),
            family=str(data.get("family", "lmi")),
            kalman=list(data.get("kalman", [])),
        )
    except (KeyError, TypeError, ValueError) as err:
        raise GainTableError(f"{source}: malformed gain table ({type(err).__name__}: {err})") from None
    if table.family not in TABLE_FAMILIES:
        raise GainTableError(f"{source}: unknown gain family {table.family!r} (known: {', '.join(TABLE_FAMILIES)})")
    if table.family == "kalman" and not table.kalman:
        raise GainTableError(f"{source}: a kalman gain table without a Kalman design")
    if system is not None:
        table.check_system(system, source=source)
    return table


def load(cls: Any, path: str | Path, *, system: LTISystem | None = None) -> Any:
    """Read and check a table file; with ``system``, also that it was made for it."""
    path = Path(path)
    if is_binary(path):
        return from_payload(cls, decode(path), source=str(path), system=system)
    try:
        text = read_text(path, exc=GainTableError, what="gain table")
    except FileNotFoundError:
        raise GainTableError(f"gain table {path} does not exist (make one with `switchobs design`)") from None
    return from_json(cls, text, source=str(path), system=system)
