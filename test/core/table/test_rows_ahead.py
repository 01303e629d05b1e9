"""A version-4 table's priors verified ahead of their use by a worker thread (``table/rows.py``): the
rows the caller gets are the stored doubles bit for bit, a row that fails its checksum is never handed
over (it raises in the caller's thread, every time), and a row verified ahead holds the bytes that
matched its digest, whatever the file holds later."""

from __future__ import annotations

import gc
import os
import threading
import time
import warnings

import pytest
from _binary_tables import flip_bit

from switchobs_core.design.kalman import design_kalman
from switchobs_core.exceptions import GainTableError
from switchobs_core.model.scenarios import paper_system
from switchobs_core.model.schedule import Cycle
from switchobs_core.table import rows as rows_mod
from switchobs_core.table.gains import GainTable, kalman_table

PAPER = paper_system()
CYCLE = Cycle.from_ts(2.0, 0.6)


@pytest.fixture(scope="module")
def table():
    return kalman_table(PAPER, [design_kalman(PAPER, CYCLE, 50.0)])


def _rows(path):
    rows = GainTable.load(path, system=PAPER).kalman[0]["periodic"]["P_prior"]
    assert isinstance(rows, rows_mod.LazyRows) and len(rows) > rows_mod.AHEAD
    return rows


def _held(rows, k, timeout=10.0):
    """Wait until the worker holds row ``k`` verified (a wait for the thread, not a time measured)."""
    end = time.monotonic() + timeout
    while k not in rows._ahead._done:
        assert time.monotonic() < end, f"row {k} not verified ahead within {timeout} s"
        time.sleep(0.002)


def test_rows_ahead_are_the_stored_doubles(table, tmp_path):
    """In order, with a jump and across the wrap of the periodic segment: every row equals the one read
    without a worker, bit for bit, read-only; the rows after the first come from the worker."""
    rows = _rows(table.save(tmp_path / "k.npz"))
    S = len(rows)
    ref = [rows._read(k).tobytes() for k in range(S)]
    jumps = {0, S // 2, S - 3, 6}           # the first row, and the first after each jump: the caller's
    order = [*range(0, 6), *range(S // 2, S // 2 + 4), *range(S - 3, S), 0, 1, 2, *range(6, 12)]
    for k in order:
        ahead = k not in jumps and k not in rows._verified
        if ahead:
            _held(rows, k)
        a = rows.row(k)
        assert a.tobytes() == ref[k] and not a.flags.writeable
    assert rows.verified() == len(set(order))
    assert rows._ahead._thread.name == "table-rows-ahead" and rows._ahead._thread in threading.enumerate()


@pytest.mark.parametrize("ahead", [0, rows_mod.AHEAD])
def test_a_row_that_fails_ahead_raises_in_the_caller(table, tmp_path, monkeypatch, ahead):
    """One bit flipped in row 5's prior before the worker reaches it: rows 0-4 and 6-9 are the stored
    doubles, row 5 raises the caller's one-line GainTableError every time (with and without a worker)."""
    monkeypatch.setattr(rows_mod, "AHEAD", ahead)
    path = table.save(tmp_path / "k.npz")
    rows = _rows(path)
    ref = {k: rows._read(k).tobytes() for k in range(10)}
    flip_bit(path, rows._offset + 5 * 8 * rows.m + 17)
    assert rows.row(0).tobytes() == ref[0]
    if ahead:
        _held(rows, 6)
        assert 5 not in rows._ahead._done
    for k in (1, 2, 3, 4):
        assert rows.row(k).tobytes() == ref[k]
    for _ in range(2):
        with pytest.raises(GainTableError, match=r"phase 5 of k0_periodic_P: checksum mismatch") as err:
            rows.row(5)
        assert "\n" not in str(err.value)
    for k in (6, 7, 8, 9):
        assert rows.row(k).tobytes() == ref[k]


def test_a_row_verified_ahead_keeps_the_bytes_that_matched(table, tmp_path):
    """Row 3 verified ahead, then rewritten in place: the caller gets the verified (stored) doubles once;
    asked for again, the row is read and verified again and refused."""
    path = table.save(tmp_path / "k.npz")
    rows = _rows(path)
    stored = rows._read(3).tobytes()
    rows.row(0)
    _held(rows, 3)
    flip_bit(path, rows._offset + 3 * 8 * rows.m)
    assert rows.row(3).tobytes() == stored
    with pytest.raises(GainTableError, match="checksum mismatch"):
        rows.row(3)


def test_the_worker_ends_with_its_table(table, tmp_path):
    """The worker holds its table weakly: once the table is gone it ends (within its 1 s poll)."""
    rows = _rows(table.save(tmp_path / "k.npz"))
    rows.row(0)
    thread = rows._ahead._thread
    assert thread.is_alive()
    del rows
    gc.collect()
    thread.join(timeout=10.0)
    assert not thread.is_alive()


def test_a_worker_that_fails_leaves_every_row_to_the_caller(table, tmp_path, monkeypatch):
    """An exception in the worker (here a MemoryError while it reads) ends the read-ahead for good: the
    rows are still the stored doubles, read by the caller; the failure is kept and warned about once."""
    path = table.save(tmp_path / "k.npz")
    rows = _rows(path)
    ref = [rows._read(k).tobytes() for k in range(8)]

    def broken(k, buf):
        raise MemoryError("no buffer")

    monkeypatch.setattr(rows, "_read_into", broken)
    with warnings.catch_warnings(record=True) as seen:
        warnings.simplefilter("always")
        assert rows.row(0).tobytes() == ref[0]      # the worker starts (and fails beside the caller)
        rows._ahead._thread.join(timeout=10.0)
        assert not rows._ahead._thread.is_alive() and isinstance(rows._ahead.failed, MemoryError)
        for k in range(1, 8):
            assert rows.row(k).tobytes() == ref[k]
    said = [str(w.message) for w in seen if issubclass(w.category, RuntimeWarning)]
    assert len(said) == 1 and "no longer verified ahead (MemoryError: no buffer)" in said[0], said
    assert rows.ahead_failure == "MemoryError: no buffer"
    assert not rows._ahead._thread.is_alive()      # not started again


def test_an_idle_worker_ends_and_starts_again(table, tmp_path, monkeypatch):
    """A worker nobody woke for IDLE_POLLS polls ends (its buffers freed); the next row that needs rows
    ahead starts it again, and the rows after it come verified from the worker."""
    monkeypatch.setattr(rows_mod, "POLL", 0.01)
    monkeypatch.setattr(rows_mod, "IDLE_POLLS", 3)
    rows = _rows(table.save(tmp_path / "k.npz"))
    ref = [rows._read(k).tobytes() for k in range(rows_mod.AHEAD + 4)]
    rows.row(0)
    _held(rows, 1)
    first = rows._ahead._thread
    first.join(timeout=10.0)
    assert not first.is_alive() and rows._ahead._done == {}
    assert rows.row(rows_mod.AHEAD + 1).tobytes() == ref[rows_mod.AHEAD + 1]     # a jump: the caller reads it
    assert rows._ahead._thread is not first and rows._ahead.failed is None
    _held(rows, rows_mod.AHEAD + 2)
    assert rows.row(rows_mod.AHEAD + 2).tobytes() == ref[rows_mod.AHEAD + 2]


@pytest.mark.skipif(not hasattr(os, "fork"), reason="needs os.fork")
def test_a_forked_child_reads_rows_with_a_worker_of_its_own(table, tmp_path):
    """The process id the rows compare with is kept by a fork hook (no system call per row): in a forked
    child it is the child's, the parent's worker is not used there (its thread does not exist in the
    child), and the child's rows are the stored doubles from a worker of its own."""
    rows = _rows(table.save(tmp_path / "k.npz"))
    ref = [rows._read(k).tobytes() for k in range(4)]
    rows.row(0)
    parent = rows._ahead
    assert parent is not None and parent.pid == os.getpid() == rows_mod._PID[0]
    r, w = os.pipe()
    pid = os.fork()
    if pid == 0:        # the child: exit code 0 only if every check holds
        ok = False
        try:
            got = [rows.row(k).tobytes() for k in (1, 2, 3)]
            ok = (rows_mod._PID[0] == os.getpid() and rows._ahead is not parent
                  and rows._ahead.pid == os.getpid() and got == ref[1:])
        finally:
            os.write(w, b"1" if ok else b"0")
            os._exit(0)
    os.close(w)
    verdict = os.read(r, 1)
    os.close(r)
    os.waitpid(pid, 0)
    assert verdict == b"1"
    assert rows_mod._PID[0] == os.getpid() and rows._ahead is parent     # the parent's own, unchanged
