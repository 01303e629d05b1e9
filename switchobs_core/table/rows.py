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
again.

Rows are used in order (a phase after the one before it), so from the first row asked for on, a
worker thread (:class:`_Ahead`) reads and verifies the next :data:`AHEAD` rows ahead of their use in
bursts, the same way (``os.pread``, ``hashlib`` and ``isfinite`` release the GIL), and hands over only
the rows that passed: :meth:`LazyRows.row` returns a row verified ahead without reading it again, and
reads and verifies any other row itself, so a row that failed ahead fails in the caller's thread with
the same message. A row verified ahead holds the bytes that matched its digest (a file rewritten in
place after they were read gives the numbers written, never other ones). The work per row is the
same (about 80 us at n = 132 here, most of it the SHA-256); it is done beside the caller's thread
instead of in it, within the sample that first visits a phase. A mismatch raises
:class:`~switchobs_core.exceptions.GainTableError` naming the file, the array and the phase, every time
that row is asked for; the numbers are never returned. Rows already verified stay usable.
"""

from __future__ import annotations

import hashlib
import os
import threading
import warnings
import weakref
from collections.abc import Iterator, Sequence
from typing import Any, BinaryIO

import numpy as np

from ..exceptions import GainTableError

__all__ = ["AHEAD", "LazyRow", "LazyRows", "OpenFile", "row_digest"]

#: How many rows after the last one asked for the worker keeps verified (about 2.2 MiB at n = 132);
#: 0: no worker (every row read and verified by the caller).
AHEAD = 32
#: The worker's poll (seconds) while nobody wakes it, and how many polls in a row it waits before it
#: ends (its buffers freed); the next row asked for starts it again.
POLL = 1.0
IDLE_POLLS = 10

_START = threading.Lock()       # one worker per table, whichever thread asks for its first row
#: This process's id, kept by a fork hook (a forked child has no worker: :meth:`LazyRows.row` starts its own)
#: instead of a system call per row.
_PID = [os.getpid()]
os.register_at_fork(after_in_child=lambda: _PID.__setitem__(0, os.getpid()))


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
        self._ahead: _Ahead | None = None
        #: Why the worker stopped verifying rows ahead (an exception in it), or None; the rows are then
        #: all read and verified by the caller.
        self.ahead_failure: str | None = None

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
        ahead = self._ahead
        if ahead is None or ahead.pid != _PID[0]:     # the first row, or a forked child (no worker there)
            with _START:
                ahead = self._ahead
                if ahead is None or ahead.pid != _PID[0]:
                    ahead = self._ahead = _Ahead(self) if AHEAD > 0 and len(self) > 1 else None
        a = None if ahead is None else ahead.take(k)
        if ahead is not None and ahead.failed is not None and self.ahead_failure is None:
            self.ahead_failure = f"{type(ahead.failed).__name__}: {ahead.failed}"
            warnings.warn(f"{self.source}: rows of {self.name} are no longer verified ahead "
                          f"({self.ahead_failure}); each is read and verified when it is used",
                          RuntimeWarning, stacklevel=2)
        if a is None:
            a = self._read(k)
        self._verified.add(k)
        return a

    def _read(self, k: int) -> np.ndarray:
        """Row ``k`` read from the file and verified, or GainTableError."""
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
        return a

    def _read_into(self, k: int, buf: np.ndarray) -> bool:
        """Row ``k`` read into ``buf`` (``m`` float64); whether it passed the checks of :meth:`_read`."""
        try:
            got = os.preadv(self._file.fd, [buf], self._offset + k * 8 * self.m)
        except OSError:
            return False
        return (got == 8 * self.m and row_digest(self.name, k, buf, self.m) == self._digests[k]
                and bool(np.isfinite(buf).all()))

    @property
    def packed(self) -> np.ndarray:
        """Every row (each verified), as one ``(S, m)`` array."""
        out = np.empty((len(self), self.m))
        for k in range(len(self)):
            out[k] = self.row(k)
        return out

    def verified(self) -> int:
        """How many distinct rows have been returned (each read and verified) so far."""
        return len(self._verified)


class _Ahead:
    """The worker that verifies the rows after the last one asked for (module docstring).

    :meth:`take` (the caller's thread) gives row ``k`` if the worker verified it, and wakes the worker
    when half of :data:`AHEAD` rows or fewer are left ahead of ``k``; the worker then reads rows
    ``k + 1, k + 2, ...`` (cyclically: a periodic segment wraps) up to ``k + AHEAD``, skipping rows
    already returned, and keeps those that pass. It holds its table weakly and ends once the table is
    gone, every row was returned, or nobody woke it for :data:`IDLE_POLLS` polls (the next :meth:`take`
    that needs rows ahead starts it again). An exception in it ends it for good (:attr:`failed`; the
    caller reads every later row itself).

    The worker reads into a pool of ``AHEAD + 2`` buffers; :meth:`take` hands the caller the buffer of
    its row (the verified bytes, read-only) and puts a new one, allocated in the caller's thread, in
    its place: the worker then writes into memory of the caller's allocator (a thread's own arena
    would give it fresh pages to fault in for every row, about 35 us a row here)."""

    def __init__(self, rows: LazyRows) -> None:
        self.pid = _PID[0]
        self._rows = weakref.ref(rows)
        self._done: dict[int, np.ndarray] = {}      # row -> the buffer holding its verified bytes
        self._free: list[np.ndarray] = []
        self._buffers = 0
        self._want = -1                 # the last row asked for
        self._upto = -1                 # the worker was last asked to read up to this row (unwrapped)
        self._wake = threading.Event()
        self.failed: BaseException | None = None
        self._thread = self._start()

    def _start(self) -> threading.Thread:
        thread = threading.Thread(target=self._run, name="table-rows-ahead", daemon=True)
        thread.start()
        return thread

    def take(self, k: int) -> np.ndarray | None:
        """Row ``k`` as the worker verified it (read-only), or None (the caller reads and verifies it)."""
        a = self._done.pop(k, None)
        if a is not None:               # handed over: a new buffer from the caller's memory takes its place
            self._free.append(np.empty_like(a))
            a.flags.writeable = False
        self._want = k
        if not AHEAD // 2 < self._upto - k <= AHEAD:     # half or fewer ahead, or a jump
            self._upto = k + AHEAD
            if self.failed is None:
                if not self._thread.is_alive():     # ended idle: started again
                    self._thread = self._start()
                self._wake.set()
        return a

    def _run(self) -> None:
        try:
            self._loop()
        except Exception as err:        # any failure only stops the read-ahead
            self.failed = err
        self._done, self._free, self._buffers = {}, [], 0   # the buffers go; a later row is the caller's

    def _loop(self) -> None:
        idle = 0
        while True:
            if not self._wake.wait(POLL):
                idle += 1
                rows = self._rows()
                if rows is None or len(rows._verified) == len(rows) or idle >= IDLE_POLLS:
                    return              # the table is gone, every row was returned (kept by its phase), or idle
                del rows                # not held while waiting
                continue
            idle = 0
            self._wake.clear()
            rows = self._rows()
            if rows is None:
                return
            self._burst(rows, self._want)
            del rows

    def _buffer(self, m: int) -> np.ndarray | None:
        """A free buffer of ``m`` float64, or None when all ``AHEAD + 2`` are taken."""
        if self._free:
            return self._free.pop()
        if self._buffers < AHEAD + 2:
            self._buffers += 1
            return np.empty(m, dtype="<f8")
        return None

    def _burst(self, rows: LazyRows, k: int) -> None:
        """Verify rows ``k + 1 .. k + AHEAD`` (cyclically) not yet returned nor held; free the buffers of
        held rows that are no longer ahead of the caller."""
        S, done, returned = len(rows), self._done, rows._verified
        want = self._want
        for i in [i for i in list(done) if not 0 < (i - want) % S <= AHEAD]:
            buf = done.pop(i, None)
            if buf is not None:
                self._free.append(buf)
        for j in range(k + 1, k + 1 + AHEAD):
            i = j % S
            if i == k or i in done or i in returned:
                continue
            if self._want - k > AHEAD // 2:
                break                   # the caller went past this burst: the next one starts where it is
            buf = self._buffer(rows.m)
            if buf is None:
                break
            if rows._read_into(i, buf):
                done[i] = buf
            else:                       # not kept: the caller reads it again and raises
                self._free.append(buf)


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
