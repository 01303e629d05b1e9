"""CycleTracker: the one owner of switching instants, residence times and cycle records."""

from __future__ import annotations

import math
from types import SimpleNamespace

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from switchobs_core.certificate import cycle_factor, paper_factors
from switchobs_core.runtime.cycles import CycleTracker, residence_limits, residence_text


def _design(h=(1.2, 0.8)):
    return SimpleNamespace(kappa=(2.0, 3.0), mu=(0.6, 0.55), eta=(1.6, 3.5), cycle=SimpleNamespace(h=h))


def _run(tr, d, switches):
    for t, c in switches:
        tr.end_residence(t)
        tr.begin(t, c, tr.limits_for(d, c))


def test_schedule_residence_limits_text_and_violations():
    d = _design()
    tr = CycleTracker(2, "periodic", None, 0.05)
    _run(tr, d, [(0.0, 1), (1.2, 2)])
    assert tr.violations == 0                  # the first residence is a lower bound: not judged low
    assert tr.limits == pytest.approx((0.75, 0.85))
    _run(tr, d, [(2.5, 1)])                    # channel 2 active 1.3 s > 0.85
    assert tr.violations == 1
    assert tr.problem_at_switch == ("schedule broken: channel 2 was active 1.300 s > the scheduled 0.8 s "
                                    "(tolerance 0.05 s)")
    res = tr.residence(3.0, d)
    assert (res.kind, res.channel, res.current, res.violations) == ("schedule", 1, 0.5, 1)
    assert res.last == pytest.approx((2, 1.3, 0.75, 0.85))
    # factors of the cycle so far: h = (0.5, 0) on the open cycle
    assert res.f == paper_factors(d, (0.5, 0.0))
    tr.reset(0.0)
    assert tr.violations == 1 and tr.residence(0.0, d) is None


def test_robust_limits_and_a2_text():
    lo, hi = residence_limits(True, (0.8, 1.2), 0.05, None)
    assert (lo, hi) == pytest.approx((0.75, 1.25))
    assert residence_limits(True, None, 0.05, None) == (0.0, math.inf)
    assert residence_text(True, 0.05, 1, 1.4, lo, hi, done=False) == (
        "A2 broken: channel 1 active 1.400 s > h_max 1.2 s (tolerance 0.05 s)")
    assert residence_text(True, 0.05, 2, 0.5, lo, hi, done=True) == (
        "A2 broken: channel 2 was active 0.500 s < h_min 0.8 s (tolerance 0.05 s)")


@settings(max_examples=50, deadline=None)
@given(h1=st.floats(0.1, 3.0), h2=st.floats(0.1, 3.0))
def test_close_cycle_record_matches_measured_durations(h1, h2):
    d = _design()
    tr = CycleTracker(2, "periodic", None, 0.05)
    _run(tr, d, [(0.0, 1), (h1, 2)])
    tr.end_residence(h1 + h2)
    rec, resync = tr.close_cycle(h1 + h2, 0, d, 0, d.cycle, sequence=True)
    assert rec.h == (h1, (h1 + h2) - h1)
    assert rec.tau == h1 + h2 and rec.order == (1, 2)
    assert rec.f == tuple(cycle_factor(k, m, e, hi, rec.tau - hi)
                          for k, m, e, hi in zip(d.kappa, d.mu, d.eta, rec.h))
    ok = abs(rec.h[0] - 1.2) <= 0.05 and abs(rec.h[1] - 0.8) <= 0.05
    assert rec.matched == ok and resync == (not ok)
