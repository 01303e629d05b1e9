"""A gain table read ahead in a worker thread: the same table as a load in the caller's thread, bit for
bit, and the same refusal (type and one-line message), raised in the caller's thread when it takes the
table; a file damaged anywhere gives the same outcome either way."""

from __future__ import annotations

import threading

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from switchobs_core.design.kalman import design_kalman
from switchobs_core.exceptions import GainTableError
from switchobs_core.model.scenarios import camera_agents, paper_system
from switchobs_core.model.schedule import Cycle
from switchobs_core.table.ahead import TableReadAhead
from switchobs_core.table.gains import GainTable, kalman_table

PAPER = paper_system()
CYCLE = Cycle.from_ts(2.0, 0.6)


@pytest.fixture(scope="module")
def table():
    return kalman_table(PAPER, [design_kalman(PAPER, CYCLE, 50.0)])


@pytest.fixture(scope="module")
def files(table, tmp_path_factory):
    d = tmp_path_factory.mktemp("ahead")
    return {"npz": table.save(d / "k.npz"), "json": table.save(d / "k.json")}


def _outcome(read) -> tuple[str, str]:
    """What reading gives: the table's JSON text (every number, the lazily read priors included), or
    the refusal's type and message."""
    try:
        return "table", read().to_json()
    except GainTableError as err:
        return type(err).__name__, str(err)


@pytest.mark.parametrize("kind", ["npz", "json"])
def test_same_table_as_a_load(files, table, kind):
    """The table taken from the worker is the one ``GainTable.load(path, system=...)`` gives: the same
    JSON text, and the same bytes in every gain, prior and error transition of its design."""
    path = files[kind]
    ahead = TableReadAhead(GainTable, path)
    got, want = ahead.table(PAPER), GainTable.load(path, system=PAPER)
    assert got.to_json() == want.to_json() == table.to_json()
    a, b = got.kalman_design([CYCLE], PAPER), want.kalman_design([CYCLE], PAPER)
    for x, y in zip(a.periodic + a.startup, b.periodic + b.startup, strict=True):
        assert x.K.tobytes() == y.K.tobytes() and x.P_prior.tobytes() == y.P_prior.tobytes()
    assert a.error_transition.tobytes() == b.error_transition.tobytes()


def test_refusals_are_the_loads_and_raised_by_table(files, tmp_path):
    """A missing file, a truncated one and a table of another system: the worker's read does not raise
    where it runs; :meth:`table` raises the exception ``load`` raises, with the same message."""
    data = files["npz"].read_bytes()
    cut = tmp_path / "cut.npz"
    cut.write_bytes(data[: len(data) // 2])
    other = camera_agents(3)
    assert other.fingerprint() != PAPER.fingerprint()
    cases = [(tmp_path / "nope.npz", PAPER), (cut, PAPER), (files["npz"], other), (files["json"], other)]
    for path, system in cases:
        ahead = TableReadAhead(GainTable, path)     # nothing raised here, whatever the file
        with pytest.raises(GainTableError) as want:
            GainTable.load(path, system=system)
        with pytest.raises(GainTableError) as got:
            ahead.table(system)
        assert str(got.value) == str(want.value) and "\n" not in str(got.value)
        assert type(got.value) is type(want.value)


def test_taken_once_then_read_again(files):
    """A second :meth:`table` reads the file again (a table of its own, equal to the first), in the
    caller's thread; the worker is a daemon thread that has ended once the table is taken."""
    ahead = TableReadAhead(GainTable, files["npz"])
    first = ahead.table(PAPER)
    assert not ahead._thread.is_alive() and ahead._thread.daemon
    second = ahead.table(PAPER)
    assert second is not first and second.to_json() == first.to_json()
    assert ahead._thread is not threading.current_thread()


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(where=st.floats(0.0, 1.0, exclude_max=True), flip=st.integers(1, 255))
def test_damaged_anywhere_same_outcome(files, tmp_path, where, flip):
    """One byte of the .npz changed anywhere (the zip structure, the header, a gain, a prior read
    lazily): read ahead or loaded in place, the same table or the same one-line refusal."""
    data = bytearray(files["npz"].read_bytes())
    i = int(where * len(data))
    data[i] ^= flip
    path = tmp_path / f"damaged_{i}_{flip}.npz"
    path.write_bytes(bytes(data))
    ahead = TableReadAhead(GainTable, path)
    assert _outcome(lambda: ahead.table(PAPER)) == _outcome(lambda: GainTable.load(path, system=PAPER))
