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
