"""The simulation's progress bar: on stderr when asked, and the numbers the same with or without it."""

from __future__ import annotations

import numpy as np
import pytest

import switchobs_core as so


@pytest.mark.parametrize("rate", [None, 50.0])
def test_progress_bar_on_stderr_and_same_numbers(paper_table, capsys, rate):
    sysm = so.paper_system()
    sched = so.PeriodicSchedule(so.Cycle.from_ts(2.0, 0.6))
    x0 = np.linspace(-1, 1, sysm.n)
    runs = [so.simulate.simulate(sysm, paper_table, sched, x0, np.zeros(sysm.n), 3.0, rate=rate, progress=p)
            for p in (False, True)]
    err = capsys.readouterr().err
    assert "it/s" in err or "sample" in err or "step" in err, err[-300:]
    assert np.array_equal(runs[0].x_hat, runs[1].x_hat)
    assert np.array_equal(runs[0].exact_bound, runs[1].exact_bound)
