"""The binary gain-table container: a ``.npz`` file holding the JSON header and the Kalman arrays.

A gain table (:mod:`switchobs_core.table.gains`) is written as JSON text, or, when its file name ends in ``.npz``, as
an uncompressed numpy ``.npz`` archive (``format_version = 5``; versions 3 and 4 are still read) with the members

* ``header``: the UTF-8 JSON of the table's payload (the JSON format's keys, the same format
  name and checks), in which the large matrices of every Kalman design are replaced by
  references ``{"$array": name}``;
* per Kalman design ``i`` and segment ``s`` (``periodic``, ``startup``): ``k{i}_{s}_P``, the prior
  covariances ``P^-`` of the S phases as the packed upper triangles (S x n(n+1)/2; a stored
  prior is exactly symmetric, so nothing is lost), ``k{i}_{s}_K``, the gains ``K`` of all phases
  flattened (row-major) one after the other, their column counts listed in the header
  (``K_cols``); and ``k{i}_E``, the period's error transition (n x n);
* (version 5) per channel ``i``, ``c{i}_T_o``, its stored observable basis (n x r_i), and per Kalman
  design ``i`` its noise model's ``k{i}_noise_Q_c`` and ``k{i}_noise_P0`` (n x n): the header's largest
  matrices, whose JSON (decimal text, parsed, then written again for the checksum) took 25-30 ms of
  a 32-agent table's 45 ms load; as arrays they are read, hashed and checked for finiteness as the
  gains are. The payload a load gives holds them as float64 arrays (the same doubles as the lists of
  the JSON format).

All arrays are float64, little-endian. Floats are stored as their 8 bytes, so a table round-trips
bit for bit.

What is verified when. The header's ``payload_sha256`` is the SHA-256 of the canonical JSON of the
header without it, followed by every array the load reads whole (name, dtype, shape, bytes, in name
order). In version 3 that is every array: loading reads and hashes the whole file, and an edited
or truncated file is refused in one line, as a JSON table is. In version 4 it is every array but the
priors ``k{i}_{s}_P``: the header lists, per segment, one SHA-256 per phase (``P_sha256``, covered by
``payload_sha256``), and a phase's prior is read from the file and verified against its own digest
the first time it is used (:mod:`switchobs_core.table.rows`; a mismatch raises
:class:`~switchobs_core.exceptions.GainTableError` naming the phase and the numbers are never used).
So at load a version-4 table has its header, gains ``K``, error transitions ``E`` and the shape of
every member checked; the gains and transitions are all the load-time re-verification
(:mod:`switchobs_core.table.check`) reads, so a table whose gains do not converge is refused at load
either way. Every number the software uses has been verified before its first use.

Size limit. Before reading an array, the file's size is checked against
:func:`size_limit`: ``MAX_FILE_BYTES`` (16 MiB, for the header and the LMI part) plus, per
stored phase, ``8 (n (n + 1) / 2 + n p_max)`` bytes (its packed prior and gain), plus
``8 n^2`` per design, at most ``MAX_BINARY_BYTES`` (4 GiB) in all. For ``camera_agents`` with M
agents (n = 4 (M + 1), p = 4) that is about 4 n^2 = 64 (M + 1)^2 bytes per phase: 74 KiB per
phase at M = 32, 5.9 KiB at M = 8. Every member, stored or compressed, is read only after its
``.npy`` header was checked against the member's size (the bytes the header claims must be the
bytes the member holds): a header claiming 2^33 doubles is refused before anything is allocated.
The header member itself is at most ``MAX_FILE_BYTES``; a version-4 header takes 68 bytes a phase
more than version 3 (the phase's digest), 0.23 MiB for the 3 525 phases of the 32-agent table.
"""

from __future__ import annotations

import functools
import hashlib
import io
import json
import os
import re
import stat
import struct
import zipfile
from collections.abc import Sequence
from pathlib import Path
from typing import Any, BinaryIO

import numpy as np

from ..exceptions import GainTableError
from ..loading import MAX_FILE_BYTES, parse_json
from .rows import LazyRows, OpenFile, row_digest

__all__ = ["MAGIC", "BINARY_VERSION", "READ_VERSIONS", "MAX_BINARY_BYTES", "is_binary", "size_limit", "encode",
           "decode", "jsonable", "packed_size", "unpack_symmetric", "PackedRows"]

#: The first bytes of a zip archive (an ``.npz`` file).
MAGIC = b"PK\x03\x04"
#: ``format_version`` of the binary container written (priors verified per phase on first use; the
#: observable bases and the noise models' matrices as arrays).
BINARY_VERSION = 5
#: Versions of the binary container read (3: every array verified at load; 4: bases and noise in the header).
READ_VERSIONS = (3, 4, 5)
#: A Kalman design's noise matrices stored as arrays from version 5 on.
_NOISE_ARRAYS = ("Q_c", "P0")
#: Largest binary table read (bytes), whatever its header says.
MAX_BINARY_BYTES = 4 * 1024 ** 3
_SEGMENTS = ("periodic", "startup")


def _lazy(header: dict[str, Any], name: str) -> bool:
    """Whether array ``name`` of a container with ``header`` is verified per row on first use, not at load."""
    return header.get("format_version") in (4, 5) and name.endswith("_P")


def _matrices_apart(header: dict[str, Any]) -> bool:
    """Whether the observable bases and the noise matrices are arrays of the container (version 5 on)."""
    return header.get("format_version") == 5


class PackedRows(Sequence):
    """The priors of a segment as read: a sequence of packed upper triangles (rows of one array),
    which a JSON table writes as full matrices again."""

    def __init__(self, packed: np.ndarray, n: int) -> None:
        self.packed, self.n = packed, n

    def __len__(self) -> int:
        return self.packed.shape[0]

    def __getitem__(self, k):  # type: ignore[override]
        return self.packed[k]


def jsonable(obj: Any) -> Any:
    """``json.dumps`` hook: an array as nested lists (the same doubles); packed priors unpacked."""
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, (PackedRows, LazyRows)):
        return [unpack_symmetric(row, obj.n).tolist() for row in obj.packed]
    raise TypeError(f"{type(obj).__name__} is not JSON serialisable")


def is_binary(path: str | Path) -> bool:
    """Whether ``path`` is a regular file that starts like a zip archive (the binary container);
    anything else (a FIFO or device too: never opened here) is left to the text reader's checks."""
    try:
        if not stat.S_ISREG(os.stat(path).st_mode):
            return False
        with open(path, "rb") as fh:
            return fh.read(4) == MAGIC
    except OSError:
        return False


def size_limit(n: int, p_max: int, phases: int, designs: int) -> int:
    """Largest file size (bytes) of a binary table with ``phases`` stored phases (module docstring)."""
    per_phase = 8 * (n * (n + 1) // 2 + n * p_max)
    return min(MAX_BINARY_BYTES, MAX_FILE_BYTES + phases * per_phase + designs * 8 * n * n)


def packed_size(m: int) -> int:
    """``n`` of a packed upper triangle of ``m = n (n + 1) / 2`` entries (ValueError otherwise)."""
    n = int((np.sqrt(8 * m + 1) - 1) / 2 + 0.5)
    if n * (n + 1) // 2 != m:
        raise ValueError(f"{m} entries are not the upper triangle of a square matrix")
    return n


@functools.lru_cache(maxsize=8)
def _triu(n: int) -> tuple[np.ndarray, np.ndarray]:
    """``np.triu_indices(n)`` and the same entries' flat indices in the transpose (read-only, per n)."""
    i, j = np.triu_indices(n)
    flat, flat_t = i * n + j, j * n + i
    flat.setflags(write=False)
    flat_t.setflags(write=False)
    return flat, flat_t


def unpack_symmetric(packed: np.ndarray, n: int) -> np.ndarray:
    """The symmetric (n, n) matrix of a packed upper triangle (row-major, ``np.triu_indices`` order)."""
    P = np.empty(n * n)
    flat, flat_t = _triu(n)
    P[flat] = packed
    P[flat_t] = packed
    return P.reshape(n, n)


def _header_hash(header: dict[str, Any]) -> Any:
    """The checksum's SHA-256 over the canonical JSON of the header (without ``payload_sha256``)."""
    return hashlib.sha256(json.dumps(header, sort_keys=True, allow_nan=False, default=jsonable).encode())


def _hash_array(h: Any, name: str, a: np.ndarray) -> None:
    h.update(f"\n{name} {a.dtype.str} {a.shape}\n".encode())
    h.update(np.ascontiguousarray(a).data)


def _digest(header: dict[str, Any], arrays: dict[str, np.ndarray]) -> str:
    """``payload_sha256``: the header's canonical JSON, then every array read at load (name, dtype, shape,
    bytes) in name order (version 4: all but the priors, which have one digest per row in the header)."""
    h = _header_hash(header)
    for name in sorted(arrays):
        if not _lazy(header, name):
            _hash_array(h, name, arrays[name])
    return h.hexdigest()


def _packed(Ps: Any, iu: tuple[np.ndarray, np.ndarray]) -> np.ndarray:
    """The priors of a segment as packed upper triangles, one row per phase."""
    if isinstance(Ps, (PackedRows, LazyRows)):
        return Ps.packed
    packed = np.empty((len(Ps), iu[0].size))
    for k, P in enumerate(Ps):
        packed[k] = np.asarray(P, dtype=float)[iu]
    return packed


def encode(payload: dict[str, Any], fh: BinaryIO, *, version: int = BINARY_VERSION) -> None:
    """Write the ``.npz`` container of a table payload to ``fh`` (module docstring; ``version`` 3, 4 or 5);
    ``payload`` is not modified."""
    if version not in READ_VERSIONS:
        raise ValueError(f"binary container version {version} (written: {', '.join(map(str, READ_VERSIONS))})")
    header = dict(payload, format_version=version, container="npz")
    arrays: dict[str, np.ndarray] = {}
    n = int(payload["system"]["n"])
    iu = np.triu_indices(n)
    if _matrices_apart(header):
        channels = []
        for i, ch in enumerate(payload["channels"]):
            arrays[f"c{i}_T_o"] = np.asarray(ch["T_o"], dtype=float).reshape(n, int(ch["r"]))
            channels.append(dict(ch, T_o={"$array": f"c{i}_T_o"}))
        header["channels"] = channels
    kalman = []
    for i, d in enumerate(payload.get("kalman", [])):
        d = dict(d)
        if _matrices_apart(header):
            noise = dict(d["noise"])
            for key in _NOISE_ARRAYS:
                arrays[f"k{i}_noise_{key}"] = np.asarray(noise[key], dtype=float).reshape(n, n)
                noise[key] = {"$array": f"k{i}_noise_{key}"}
            d["noise"] = noise
        for seg in _SEGMENTS:
            ph = dict(d[seg])
            Ps = ph.pop("P_prior")
            Ks = [np.asarray(K, dtype=float).reshape(n, -1) for K in ph.pop("K")]
            name = f"k{i}_{seg}_P"
            packed = arrays[name] = _packed(Ps, iu)
            arrays[f"k{i}_{seg}_K"] = np.concatenate([K.ravel() for K in Ks]) if Ks else np.zeros(0)
            ph.update(P_prior={"$array": name}, K={"$array": f"k{i}_{seg}_K"},
                      K_cols=[int(K.shape[1]) for K in Ks])
            if _lazy(header, name):
                ph["P_sha256"] = [row_digest(name, k, row, packed.shape[1]) for k, row in enumerate(packed)]
            d[seg] = ph
        arrays[f"k{i}_E"] = np.asarray(d.pop("error_transition"), dtype=float)
        d["error_transition"] = {"$array": f"k{i}_E"}
        kalman.append(d)
    header["kalman"] = kalman
    for name, a in arrays.items():
        if not np.all(np.isfinite(a)):
            raise GainTableError(f"gain table: non-finite number in {name}")
    header["payload_sha256"] = _digest(header, arrays)
    text = json.dumps(header, sort_keys=True, allow_nan=False, default=jsonable).encode()
    np.savez(fh, header=np.frombuffer(text, dtype=np.uint8), **arrays)


def _refused(source: str, why: str) -> GainTableError:
    return GainTableError(f"{source}: not a complete binary gain table ({why}); the file may be truncated or "
                          "edited: design it again")


def decode(path: str | Path, *, source: str | None = None) -> dict[str, Any]:
    """The checked payload of a binary table (the JSON format's dict, with arrays where it has
    matrices: the priors as packed upper triangles, the gains, the error transition). In a version-4
    file the priors are :class:`~switchobs_core.table.rows.LazyRows`: read and verified per phase on
    first use, from the file handle opened here (module docstring).

    Raises
    ------
    GainTableError
        Not a complete archive, a header or array that is not the one written, a file larger
        than :func:`size_limit` allows, or a checksum mismatch (one line each).
    """
    source = str(path) if source is None else source
    try:
        fh = open(path, "rb")       # kept open by the lazily read rows of a version-4 file
    except OSError as err:
        raise _refused(source, str(err) or type(err).__name__) from None
    keep = False
    try:
        payload, keep = _decode(fh, source)
        return payload
    finally:
        if not keep:
            fh.close()


def _decode(fh: BinaryIO, source: str) -> tuple[dict[str, Any], bool]:
    """:func:`decode` from the open file ``fh``; and whether rows read later need ``fh`` open."""
    try:
        size = os.fstat(fh.fileno()).st_size
        if size > MAX_BINARY_BYTES:
            raise GainTableError(f"gain table {source} is {size / 2**20:.1f} MiB, larger than "
                                 f"{MAX_BINARY_BYTES / 2**20:.0f} MiB, the limit for any binary table")
        zf = zipfile.ZipFile(fh)
    except (zipfile.BadZipFile, OSError, ValueError, EOFError) as err:
        raise _refused(source, str(err) or type(err).__name__) from None
    with zf:
        try:
            info = {i.filename: i for i in zf.infolist()}
            hi = info.get("header.npy")
            if hi is None or hi.file_size > MAX_FILE_BYTES:
                raise _refused(source, "header missing or too large")
            raw = _npy_from_bytes(zf.read(hi))         # at most file_size bytes: checked above
            text = raw.tobytes().decode("utf-8")
        except GainTableError:
            raise
        except (zipfile.BadZipFile, OSError, ValueError, EOFError, UnicodeDecodeError) as err:
            raise _refused(source, f"header: {err}") from None
        header = parse_json(text, exc=GainTableError, source=source)
        if not isinstance(header, dict) or header.get("format_version") not in READ_VERSIONS:
            raise _refused(source, f"format version {header.get('format_version')!r} in a binary container"
                           if isinstance(header, dict) else "header is not an object")
        refs = _array_refs(header, source)
        n, p_max, phases = refs["n"], refs["p_max"], refs["phases"]
        limit = size_limit(n, p_max, phases, len(header.get("kalman", [])))
        if size > limit:
            raise GainTableError(f"gain table {source} is {size / 2**20:.1f} MiB, larger than {limit / 2**20:.1f} MiB, "
                                 f"the limit for a table of n = {n} states and {phases} stored phases")
        digest = header.pop("payload_sha256", None)
        if digest is None:
            raise GainTableError(f"{source}: the checksum (payload_sha256) is missing: the file was not written by "
                                 "switchobs or was edited; design it again")
        h = _header_hash(header)
        file = OpenFile(fh)
        arrays: dict[str, Any] = {}
        nonfinite: list[str] = []
        for name in sorted(refs["shapes"]):             # the checksum's order
            shape = refs["shapes"][name]
            zi = info.get(f"{name}.npy")
            want = 8 * int(np.prod(shape))
            if zi is None or zi.file_size > want + 4096:
                raise _refused(source, f"array {name} missing or larger than its {want} bytes")
            try:
                if _lazy(header, name):
                    arrays[name] = _lazy_member(zf, zi, name, shape, refs["digests"][name], n, source, file)
                    continue
                a, finite = _read_member(zf, zi, name, shape, h)
            except _WrongArray as err:
                raise _refused(source, f"array {name} is {err}, not float64 {shape}") from None
            except (zipfile.BadZipFile, OSError, ValueError, EOFError, struct.error) as err:
                raise _refused(source, f"array {name}: {err}") from None
            arrays[name] = a
            if not finite:
                nonfinite.append(name)
    if digest != h.hexdigest():
        raise GainTableError(f"{source}: checksum mismatch: the file was modified or corrupted after it was written")
    if nonfinite:
        raise GainTableError(f"{source}: non-finite number in {nonfinite[0]}")
    return _inflate(header, arrays, n), any(isinstance(a, LazyRows) for a in arrays.values())


def _lazy_member(zf: zipfile.ZipFile, zi: zipfile.ZipInfo, name: str, shape: tuple[int, ...],
                 digests: list[str], n: int, source: str, file: OpenFile) -> LazyRows | np.ndarray:
    """The rows of a member verified per row on first use: its ``.npy`` header checked now (as
    :func:`_read_member` does), nothing of its data read. A compressed member (not what :func:`encode`
    writes) is read whole and every row verified now."""
    S, m = shape
    if zi.compress_type != zipfile.ZIP_STORED or zf.fp is None:
        a = _npy_from_bytes(zf.read(zi))
        _expect(a.dtype, a.shape, shape)
        for k in range(S):
            if row_digest(name, k, a[k], m) != digests[k]:
                raise GainTableError(f"{source}: phase {k} of {name}: checksum mismatch: the file was modified "
                                     "or corrupted after it was written")
        if not np.isfinite(a).all():
            raise GainTableError(f"{source}: non-finite number in {name}")
        return a
    fh = zf.fp
    start = _data_start(fh, zi)
    fh.seek(start)
    got, dtype, _ = _npy_header(fh, lambda: start + zi.file_size - fh.tell())
    _expect(dtype, got, shape)
    return LazyRows(file, fh.tell(), name, digests, m, n, source)


class _WrongArray(ValueError):
    """A member whose ``.npy`` header is not the float64 array of the shape the table's header declares."""


#: Bytes read, hashed and checked for non-finite numbers at a time (stays in the cache between the three).
_CHUNK = 1 << 21


def _read_member(zf: zipfile.ZipFile, zi: zipfile.ZipInfo, name: str, shape: tuple[int, ...],
                 h: Any) -> tuple[np.ndarray, bool]:
    """The array of one ``.npy`` member and whether it is all finite; its name, dtype, shape and bytes
    go into the checksum ``h`` (:func:`_digest`'s order). Its header is checked against the member's
    size before anything is allocated (:func:`_npy_header`), and against ``shape`` (float64) before
    anything is read (:class:`_WrongArray`). A stored member (what :func:`encode` writes) is read in
    place, a slice of the array at a time, each slice hashed and checked while it is in the cache (one
    pass over the data; integrity is the SHA-256's job); a compressed one is decompressed to at most its
    ``file_size`` (which the caller bounded) and read from those bytes."""
    if zi.compress_type != zipfile.ZIP_STORED or zf.fp is None:
        a = _npy_from_bytes(zf.read(zi))
        _expect(a.dtype, a.shape, shape)
        _hash_array(h, name, a)
        return a, bool(np.isfinite(a).all())
    fh = zf.fp
    start = _data_start(fh, zi)
    fh.seek(start)
    got, dtype, count = _npy_header(fh, lambda: start + zi.file_size - fh.tell())
    _expect(dtype, got, shape)
    a = np.empty(count, dtype=dtype)
    h.update(f"\n{name} {a.dtype.str} {tuple(got)}\n".encode())
    raw = memoryview(a).cast("B")
    step = _CHUNK // a.itemsize
    finite = True
    for lo in range(0, count, step):
        part = raw[lo * a.itemsize:min(count, lo + step) * a.itemsize]
        if fh.readinto(part) != len(part):
            raise ValueError("member shorter than its header says")
        h.update(part)
        finite = finite and bool(np.isfinite(a[lo:lo + step]).all())
    return a.reshape(got), finite


def _data_start(fh: BinaryIO, zi: zipfile.ZipInfo) -> int:
    """The offset in the archive of a stored member's first byte (after its local header)."""
    fh.seek(zi.header_offset)
    head = fh.read(30)
    if len(head) != 30 or head[:4] != b"PK\x03\x04":
        raise ValueError("bad local header")
    name_len, extra_len = struct.unpack("<HH", head[26:30])
    return zi.header_offset + 30 + name_len + extra_len


def _expect(dtype: np.dtype, got: tuple[int, ...], shape: tuple[int, ...]) -> None:
    if dtype != np.dtype("<f8") or tuple(got) != tuple(shape):
        raise _WrongArray(f"{dtype} {tuple(got)}")


def _npy_from_bytes(raw: bytes) -> np.ndarray:
    """The array of a whole ``.npy`` member's bytes (:func:`_npy_header` checks before allocating)."""
    fh = io.BytesIO(raw)
    shape, dtype, count = _npy_header(fh, lambda: len(raw) - fh.tell())
    return np.frombuffer(raw, dtype=dtype, count=count, offset=fh.tell()).reshape(shape).copy()


def _npy_header(fh: BinaryIO, remaining) -> tuple[tuple[int, ...], np.dtype, int]:
    """``(shape, dtype, count)`` of the ``.npy`` header at ``fh``; ``remaining()`` is the number of
    bytes of the member after the header. ValueError, before any allocation, if the data the header
    claims is not exactly what the member holds (a header claiming 2^33 doubles over a few kB), or if
    it is not a plain array (objects, Fortran order, an unknown format version)."""
    version = np.lib.format.read_magic(fh)
    if version == (1, 0):
        shape, fortran, dtype = np.lib.format.read_array_header_1_0(fh, max_header_size=4096)
    elif version == (2, 0):
        shape, fortran, dtype = np.lib.format.read_array_header_2_0(fh, max_header_size=4096)
    else:
        raise ValueError(f".npy format version {version[0]}.{version[1]} is not one this container writes")
    if dtype.hasobject or fortran:
        raise ValueError("its .npy header describes objects or a Fortran-ordered array")
    count = 1
    for d in shape:
        count *= int(d)
    claims, holds = count * dtype.itemsize, remaining()
    if claims != holds:
        raise ValueError(f"its .npy header claims {claims} bytes; the member holds {holds}")
    return shape, dtype, count


def _array_refs(header: dict[str, Any], source: str) -> dict[str, Any]:
    """Sizes the header declares: n, largest p, stored phases and every array's shape."""
    try:
        n = int(header["system"]["n"])
        p_max = max(int(v) for v in header["system"]["p"])
        if not (1 <= n <= 100_000 and 1 <= p_max <= 100_000):
            raise ValueError("n or p out of range")
        shapes: dict[str, tuple[int, ...]] = {}
        digests: dict[str, list[str]] = {}
        phases = 0
        for i, d in enumerate(header.get("kalman", [])):
            for seg in _SEGMENTS:
                ph = d[seg]
                S = len(ph["channel"])
                cols = [int(c) for c in ph["K_cols"]]
                if len(cols) != S or any(c < 0 or c > p_max for c in cols):
                    raise ValueError(f"kalman[{i}].{seg}.K_cols")
                phases += S
                shapes[f"k{i}_{seg}_P"] = (S, n * (n + 1) // 2)
                if _lazy(header, f"k{i}_{seg}_P"):
                    dg = ph["P_sha256"]
                    if not (isinstance(dg, list) and len(dg) == S and _all_sha256(dg)):
                        raise ValueError(f"kalman[{i}].{seg}.P_sha256")
                    digests[f"k{i}_{seg}_P"] = dg
                shapes[f"k{i}_{seg}_K"] = (n * sum(cols),)
            shapes[f"k{i}_E"] = (n, n)
        if _matrices_apart(header):     # within MAX_FILE_BYTES, which their longer JSON text took in version 4
            for i, ch in enumerate(header["channels"]):
                r = ch["r"]
                if isinstance(r, bool) or not isinstance(r, int) or not 1 <= r <= n:
                    raise ValueError(f"channels[{i}].r")
                shapes[f"c{i}_T_o"] = (n, r)
            for i, d in enumerate(header.get("kalman", [])):
                if not isinstance(d.get("noise"), dict):        # its matrices are put in it (_inflate)
                    raise ValueError(f"kalman[{i}].noise")
                for key in _NOISE_ARRAYS:
                    shapes[f"k{i}_noise_{key}"] = (n, n)
    except (KeyError, TypeError, ValueError, AttributeError) as err:
        raise _refused(source, f"header: bad or missing {err}") from None
    return {"n": n, "p_max": p_max, "phases": phases, "shapes": shapes, "digests": digests}


_SHA256 = re.compile(r"[0-9a-f]{64}")


_HEX = re.compile(r"[0-9a-f]*")


def _is_sha256(x: Any) -> bool:
    return isinstance(x, str) and _SHA256.fullmatch(x) is not None


def _all_sha256(xs: list) -> bool:
    """Whether every item is a SHA-256 hex digest (:func:`_is_sha256`): 64 characters each, the lot of them
    lower-case hex, in one match (3 525 digests in the 32-agent table)."""
    return all(isinstance(x, str) and len(x) == 64 for x in xs) and _HEX.fullmatch("".join(xs)) is not None


def _inflate(header: dict[str, Any], arrays: dict[str, np.ndarray], n: int) -> dict[str, Any]:
    """The payload with the references replaced by the matrices (priors as packed rows, gains split)."""
    payload = dict(header, format_version=2)
    payload.pop("container", None)
    apart = _matrices_apart(header)
    if apart:
        payload["channels"] = [dict(ch, T_o=arrays[f"c{i}_T_o"]) for i, ch in enumerate(header["channels"])]
    kalman = []
    for i, d in enumerate(header.get("kalman", [])):
        d = dict(d)
        if apart:
            d["noise"] = dict(d["noise"], **{key: arrays[f"k{i}_noise_{key}"] for key in _NOISE_ARRAYS})
        for seg in _SEGMENTS:
            ph = dict(d[seg])
            packed = arrays[f"k{i}_{seg}_P"]      # rows stay packed (or unread): KalmanPhase unpacks on use
            flat = arrays[f"k{i}_{seg}_K"]
            Ks, off = [], 0
            for c in ph.pop("K_cols"):
                Ks.append(flat[off:off + n * c].reshape(n, c))
                off += n * c
            ph.pop("P_sha256", None)
            ph.update(P_prior=packed if isinstance(packed, LazyRows) else PackedRows(packed, n), K=Ks)
            d[seg] = ph
        d["error_transition"] = arrays[f"k{i}_E"]
        kalman.append(d)
    payload["kalman"] = kalman
    return payload
