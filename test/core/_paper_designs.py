"""Designs with the paper's selected decay rates, shared by the runtime tests (not a test module)."""

from __future__ import annotations

from switchobs_core.design.lmi import design_table
from switchobs_core.model.schedule import Cycle

PERIODIC = Cycle.from_ts(2.0, 0.6)
NONPERIODIC = [Cycle.from_ts(4.0, 0.5), Cycle.from_ts(3.0, 0.6), Cycle.from_ts(3.0, 0.6), Cycle.from_ts(2.0, 0.4)]


def paper_table(system, robust=None):
    """Table with (2, 0.6) at (1.6, 3.5) and Table T:eta_values' selected rates."""
    cycles = [PERIODIC, NONPERIODIC[0], NONPERIODIC[1], NONPERIODIC[3]]
    etas = [(1.6, 3.5), (1.2, 1.1), (1.0, 2.2), (3.5, 1.5)]
    return design_table(system, cycles=cycles, etas=etas, robust=robust, progress=False)
