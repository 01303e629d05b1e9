"""The Kalman design's progress bar: its steps on stderr when asked, and the same design without it."""

from __future__ import annotations

import numpy as np

import switchobs_core as so


def test_kalman_design_progress_names_its_steps_and_changes_nothing(capsys):
    sysm = so.paper_system()
    cyc = so.Cycle.from_ts(2.0, 0.6)
    quiet = so.design_kalman(sysm, cyc, 20.0)
    shown = so.design_kalman(sysm, cyc, 20.0, progress=True)
    err = capsys.readouterr().err
    for step in ("sample pattern", "detectability", "doubling", "start-up", "error transition"):
        assert step in err, err[-400:]
    assert len(quiet.periodic) == len(shown.periodic) == 40
    assert all(np.array_equal(a.K, b.K) for a, b in zip(quiet.periodic, shown.periodic))
