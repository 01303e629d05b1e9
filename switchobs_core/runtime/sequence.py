"""Which design's gains are in use: the observer's schedule modes and its cycle records.

A change of channel is a switching instant (e:switching_instants); two consecutive starts of
channel 1 bound a switching cycle (e:tau_k, e:s_k), written for N channels visited in the cyclic
order 1, 2, ..., N. The gains come from a :class:`switchobs_core.table.gains.GainTable`, by mode:

``periodic``
    ``cycles=[c]``: one design for every cycle (the paper's periodic case).
``sequence``
    ``cycles=[c_0, c_1, ...]``: cycle k uses the design of ``c_{k mod K}`` (the paper's
    nonperiodic case, Table ``T:eta_values``), re-synced after a cycle that broke its promise.
``robust``
    the table's residence-time-box design ``table.robust``, meant for any schedule
    with ``h_min <= h_i <= h_max`` (assumption A2).

At the end of every cycle a :class:`~switchobs_core.runtime.cycles.CycleRecord` stores the
measured ``tau_k``, ``h_k``, ``s_k``, the paper's factors
``f_ii = kappa_i exp(mu_i (tau - h_i) - eta_i h_i)`` (e:f11_le_delta_main) for the *measured*
durations and the gains used, and whether the cycle matched the promise (order 1..N, durations
within ``match_tol`` of the scheduled cycle; in robust mode, A2's box). The residences
themselves are :class:`~switchobs_core.runtime.cycles.CycleTracker`'s.
"""

from __future__ import annotations

from collections import deque
from typing import Any

from .cycles import CycleTracker

__all__ = ["DesignSequence"]


class DesignSequence:
    """The design in use and the completed cycles of one observer run (module docstring).

    ``DesignSequence(designs, promised, mode, N, bounds, match_tol, t0, max_records)``:
    ``designs`` the gain sets of the mode and ``promised`` their cycles (None in robust mode).
    The partial cycle before the first channel-1 start uses design 0.

    Attributes
    ----------
    cycles : CycleTracker
        The residences and the cycle so far.
    records : deque of CycleRecord
        The completed cycles, oldest first (at most ``max_records``).
    resyncs : int
        Re-syncs of sequence mode since the reset.
    """

    def __init__(self, designs: tuple, promised: tuple, mode: str, N: int, bounds: tuple[float, float] | None,
                 match_tol: float, t0: float, max_records: int) -> None:
        self.designs = designs
        self.promised = promised
        self.sequence = mode == "sequence"
        self.records: deque = deque(maxlen=int(max_records))
        self.cycles = CycleTracker(N, mode, bounds, match_tol, float(t0))
        self.reset(t0)

    def reset(self, t0: float) -> None:
        """Forget the switching history (the tracker keeps its violation count)."""
        self._k = -1
        self._phase = 0     # sequence mode: offset of the design index, re-synced on mismatch
        self.resyncs = 0
        self.cycles.reset(t0)
        self.records.clear()

    @property
    def index(self) -> int:
        """Index into ``designs`` of the gains in use: ``(k + phase) mod K`` for cycle ``k``."""
        return (max(self._k, 0) + self._phase) % len(self.designs)

    @property
    def design(self) -> Any:
        """The design whose gains are in use."""
        return self.designs[self.index]

    def switch(self, t: float, channel: int) -> Any:
        """Bookkeeping at the switching instant ``t`` to ``channel``: the residence that ends, the
        cycle that a channel-1 start closes; returns the design in use from ``t`` on."""
        cyc = self.cycles
        cyc.end_residence(t)
        if channel == 1:
            if cyc.cycle_start is not None:
                self._close_cycle(t)
            self._k += 1
        d = self.design
        cyc.begin(t, channel, cyc.limits_for(d, channel))
        return d

    def _close_cycle(self, t: float) -> None:
        di = self.index
        rec, resync = self.cycles.close_cycle(t, self._k, self.designs[di], di, self.promised[di], self.sequence)
        if resync:
            self._resync(rec.h)
        self.records.append(rec)

    def _resync(self, h: tuple) -> None:
        """Sequence mode: after a cycle that did not match its promise (a late start, a reset,
        a skipped cycle), find the first cycle of the sequence it did match and continue the
        sequence from there, so the next cycle uses the gains of the one after it. Repeated
        cycle types (the paper's (3, 0.6) twice) are resolved by the following mismatches."""
        K = len(self.promised)
        for j, c in enumerate(self.promised):
            if self.cycles.matches(h, c):
                self._phase = (j - self._k) % K
                self.resyncs += 1
                return
