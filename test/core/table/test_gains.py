"""Gain table: round trip, integrity checks, lookup tolerance, certification of observed cycles."""

from __future__ import annotations

import json

import numpy as np
import pytest

from switchobs_core import paper as P
from switchobs_core.exceptions import GainTableError
from switchobs_core.model.scenarios import camera_agents
from switchobs_core.model.schedule import Cycle
from switchobs_core.table.gains import GainTable


@pytest.fixture(scope="module")
def table(paper_designer):
    return paper_designer.table([Cycle.from_ts(*r[0]) for r in P.TABLE], robust=(0.8, 1.2))


@pytest.fixture()
def saved(table, tmp_path):
    return table.save(tmp_path / "gains.json")


def test_round_trip_is_exact(table, saved, paper):
    back = GainTable.load(saved, system=paper)
    assert back.fingerprint == paper.fingerprint() and back.delta == (0.99, 0.99)
    assert len(back.designs) == 4 and back.robust is not None
    for a, b in zip(table.designs + [table.robust], back.designs + [back.robust]):
        assert a.label() == b.label() and a.eta == b.eta and a.f == b.f
        for La, Lb in zip(a.L, b.L):
            assert np.array_equal(La, Lb)
    # kappa curves are stored and monotone
    e, k = back.kappa_curve(1)
    assert len(e) > 10 and np.all(np.diff(k) >= 0)
    # save is atomic: no temporary file is left behind
    assert sorted(p.name for p in saved.parent.iterdir()) == ["gains.json"]


def test_table_for_another_system_refused(saved):
    with pytest.raises(GainTableError, match="designed for another system"):
        GainTable.load(saved, system=camera_agents(3))


def test_truncated_file_refused(saved):
    text = saved.read_text()
    saved.write_text(text[: len(text) // 2])
    with pytest.raises(GainTableError, match="truncated"):
        GainTable.load(saved)


def test_nan_refused(saved):
    data = json.loads(saved.read_text())
    data["designs"][0]["channels"][0]["L"][0][0] = float("nan")
    saved.write_text(json.dumps(data))
    with pytest.raises(GainTableError, match="non-finite number"):
        GainTable.load(saved)


def test_edited_number_fails_checksum(saved):
    data = json.loads(saved.read_text())
    data["designs"][0]["channels"][0]["eta"] = 99.0
    saved.write_text(json.dumps(data))
    with pytest.raises(GainTableError, match="checksum mismatch"):
        GainTable.load(saved)


def test_wrong_version_and_not_a_table(saved, tmp_path):
    data = json.loads(saved.read_text())
    data["format_version"] = 99
    saved.write_text(json.dumps(data))
    with pytest.raises(GainTableError, match="format version 99 is not supported"):
        GainTable.load(saved)
    other = tmp_path / "x.json"
    other.write_text('{"hello": 1}')
    with pytest.raises(GainTableError, match="not a switchobs gain table"):
        GainTable.load(other)
    with pytest.raises(GainTableError, match="does not exist"):
        GainTable.load(tmp_path / "missing.json")


def test_lookup_tolerance(table):
    assert table.lookup(Cycle.from_ts(2.0, 0.6 + 1e-9)).cycle.matches(Cycle.from_ts(2.0, 0.6))
    with pytest.raises(GainTableError, match=r"no design for cycle \(2 s, 0.61\).*designed cycles: \(2 s, 0.6\)"):
        table.lookup(Cycle.from_ts(2.0, 0.61))
    assert table.find(Cycle.from_ts(2.0, 0.61)) is None


def test_certifies_observed_cycles(table):
    d = table.lookup(Cycle.from_ts(2.0, 0.6))  # h = (1.2, 0.8)
    # the design point itself is dominated (trivially) and certified
    same = d.certifies(Cycle((1.2, 0.8)))
    assert same.dominated and same.ok and same.f == pytest.approx(d.f)
    # with two channels a longer h_2 is a longer inactive time of channel 1, so the
    # sufficient dominance rule fails, but the direct check of the paper's factor passes
    longer = d.certifies(Cycle((1.25, 0.85)))
    assert not longer.dominated and longer.ok
    assert longer.f[0] == pytest.approx(d.kappa[0] * np.exp(d.mu[0] * 0.85 - d.eta[0] * 1.25))
    # channel 1 active only 0.9 s instead of 1.2 s: the factor exceeds delta
    worse = d.certifies(Cycle((0.9, 0.8)))
    assert not worse.dominated and not worse.ok
    k, mu, eta = d.kappa[0], d.mu[0], d.eta[0]
    assert worse.f[0] == pytest.approx(k * np.exp(mu * 0.8 - eta * 0.9))
    # the robust design certifies a cycle inside its box
    assert table.robust in table.certifying(Cycle((1.1, 0.9)))
