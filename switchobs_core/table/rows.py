"""Rows of a binary table's array read from the file on first use, each verified against its own SHA-256.

A version-4 binary gain table (:mod:`switchobs_core.table.container`) stores the priors ``P^-`` of a
Kalman design's segment (the bulk of a large table: 247 of 251 MiB at 32 agents) as one array whose
rows are the phases, and the header lists one SHA-256 per row (``P_sha256``). Loading the table
verifies the header and every other array whole (the checksum ``payload_sha256`` covers the header,
so it covers these row digests), and reads no prior. The first time a phase's prior is asked for,
:meth:`LazyRows.row` reads that row from the file handle opened when the table was loaded (a file
replaced by a rename since then is not seen; one rewritten in place is caught below), into memory of
its own (never a mapping of the file), computes the SHA-256 of the row's name, index, dtype, shape
and bytes, and compares it with the row's digest; it also checks that every number is finite. Only
then is the row returned. The rows are not kept here (the phase keeps its unpacked matrix:
:class:`~switchobs_core.table.kalman.KalmanPhase`); a row asked for again is read and verified
again. A mismatch raises
:class:`~switchobs_core.exceptions.GainTableError` naming the file, the array and the phase, every time
that row is asked for; the numbers are never returned. Rows already verified stay usable.
"""

from __future__ import annotations

import hashlib
import os
import weakref
from collections.abc import Iterator, Sequence
from typing import Any, BinaryIO

import numpy as np

from ..exceptions import GainTableError

__all__ = ["LazyRow", "LazyRows", "OpenFile", "row_digest"]


def row_digest(name: str, k: int, row: np.ndarray | bytes | memoryview, m: int) -> str:
    """The SHA-256 (hex) of row ``k`` of array ``name`` (``m`` float64 numbers): the line
    ``"{name}[{k}] <f8 ({m},)"`` and a newline, then the row's bytes."""
    h = hashlib.sha256(f"{name}[{k}] <f8 ({m},)\n".encode())
    h.update(row if not isinstance(row, np.ndarray) else np.ascontiguousarray(row).data)
    return h.hexdigest()


class OpenFile:
    """A file handle shared by the :class:`LazyRows` of one table, closed when the last of them is gone."""

    def __init__(self, fh: BinaryIO) -> None:
        self.fd = fh.fileno()
        self._close = weakref.finalize(self, fh.close)


class LazyRows(Sequence):
    """The ``S`` rows of ``m`` float64 numbers of array ``name`` at byte ``offset`` of the open file
    ``file``, each verified against ``digests[k]`` whenever it is read (module docstring). Indexing gives a
    :class:`LazyRow` (nothing read); :meth:`row` the verified numbers; :attr:`packed` all of them
    (every row verified), for writing the table again."""

    def __init__(self, file: OpenFile, offset: int, name: str, digests: Sequence[str], m: int, n: int,
                 source: str) -> None:
        self._file = file
        self._offset, self.name, self._digests, self.m, self.n = offset, name, tuple(digests), m, n
        self.source = source
        self._verified: set[int] = set()

    def __len__(self) -> int:
        return len(self._digests)

    def __getitem__(self, k):  # type: ignore[override]
        if isinstance(k, slice):
            return [LazyRow(self, i) for i in range(len(self))[k]]
        if not -len(self) <= k < len(self):
            raise IndexError(k)
        return LazyRow(self, k % len(self))

    def __iter__(self) -> Iterator[LazyRow]:
        return (LazyRow(self, k) for k in range(len(self)))

    def row(self, k: int) -> np.ndarray:
        """Row ``k``, read and verified (module docstring); read-only."""
        size = 8 * self.m
        where = f"{self.source}: phase {k} of {self.name}"
        try:
            raw = os.pread(self._file.fd, size, self._offset + k * size)
        except OSError as err:
            raise GainTableError(f"{where} cannot be read ({err}); the table is not used for it") from None
        if len(raw) != size:
            raise GainTableError(f"{where}: the file ends {size - len(raw)} bytes early (truncated since it "
                                 "was loaded?); the table is not used for it")
        if row_digest(self.name, k, raw, self.m) != self._digests[k]:
            raise GainTableError(f"{where}: checksum mismatch: the file was modified or corrupted after it was "
                                 "written; the table is not used for this phase: design it again")
        a = np.frombuffer(raw, dtype="<f8")
        if not np.isfinite(a).all():
            raise GainTableError(f"{where}: non-finite number; the table is not used for this phase")
        self._verified.add(k)
        return a

    @property
    def packed(self) -> np.ndarray:
        """Every row (each verified), as one ``(S, m)`` array."""
        out = np.empty((len(self), self.m))
        for k in range(len(self)):
            out[k] = self.row(k)
        return out

    def verified(self) -> int:
        """How many distinct rows have been read and verified so far."""
        return len(self._verified)


class LazyRow:
    """Row ``k`` of :class:`LazyRows`: :meth:`load` reads and verifies it."""

    __slots__ = ("rows", "k")

    def __init__(self, rows: LazyRows, k: int) -> None:
        self.rows, self.k = rows, k

    @property
    def n(self) -> int:
        """The matrix size whose packed upper triangle the row is."""
        return self.rows.n

    def load(self) -> np.ndarray:
        """The verified numbers (:meth:`LazyRows.row`), read now."""
        return self.rows.row(self.k)

    def __array__(self, dtype: Any = None, copy: Any = None) -> np.ndarray:
        a = self.load()
        return a if dtype is None else a.astype(dtype)
