"""Shared fixtures of the core tests (no ROS needed)."""

from __future__ import annotations

import pytest

from switchobs_core.design.lmi import Designer
from switchobs_core.model.scenarios import paper_system


@pytest.fixture(scope="session")
def paper():
    """The paper's 12-state camera/two-agent system."""
    return paper_system()


@pytest.fixture(scope="session")
def paper_designer(paper):
    """One designer for the session: its kappa curves are cached across tests."""
    return Designer(paper, delta=0.99)


@pytest.fixture(scope="session")
def paper_table(paper_designer):
    """The paper's periodic (2 s, 0.6) LMI table, designed once per session."""
    from switchobs_core.model.schedule import Cycle

    return paper_designer.table([Cycle.from_ts(2.0, 0.6)], progress=False)


@pytest.fixture(scope="session")
def agents10():
    """camera_agents(10) (n = 44, above the sparse forms' threshold) with its 50 Hz Kalman table for
    residences of 0.1 s, designed once per session: ``(system, cycle, table, schedule, x)``, ``x``
    a state with the bodies' positions in [-3, 3] m (seeded) and no velocity."""
    import numpy as np

    import switchobs_core as so

    system = so.camera_agents(10)
    cycle = so.Cycle((0.1,) * 10)
    table = so.kalman_table(system, [so.design_kalman(system, cycle, 50.0)])
    rng = np.random.default_rng(5)
    x = np.zeros(system.n)
    x[0::4], x[1::4] = rng.uniform(-3, 3, 11), rng.uniform(-3, 3, 11)
    return system, cycle, table, so.PeriodicSchedule(cycle), x
