"""Pairing: the sources' messages with one header stamp (within the clock tolerance) form one sample.

An input source (:class:`~switchobs_ros.sources.Source`, from the system's input
specification) feeds some rows of a channel's output ``y_i = C_i x`` (e:outputs).
Its messages with the same header stamp are the parts of one sample (:class:`Pending`); with a
clock tolerance ``d`` (``clock_tolerance_ms``: the sources' clocks disagree by up to it) a part
joins the nearest sample stamped within ``d`` that lacks its source, and the sample carries the
stamp of its channel-specific part (the shared part's stamp is off by at most ``d``, an error the
bounds include: :mod:`switchobs_core.bounds.stamp`). A sample
is *complete* when every source its channel needs has arrived. :class:`Pairing` keeps the
samples by stamp (at most :data:`MAX_PENDING`) until the pipeline answers them, and reads a
sample as a :class:`~switchobs_core.model.measurement.Measurement` of a channel. A part whose partners
do not come (a newer sample completes, or its pairing timeout passes) is used alone, with the
rows it holds.

:class:`DeadTime`: after a switch the camera turns and only the shared rows come
(``schedule.dead_time`` d > 0). From the first shared-rows sample after a channel change (stamp
``s_0``) until the first channel-specific part of the new channel, a shared-rows sample stamped
before ``s_0 + d - (its period)`` is certainly blind (``s_0`` is at most one period after the
switching instant): it is complete alone and is answered at once.
"""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np

from switchobs_core.model.measurement import Measurement

from .sources import Source

__all__ = ["MAX_PENDING", "DeadTime", "Pairing", "Part", "Pending"]

#: Samples kept waiting for their partners or for their channel (a backlog, the reorder window:
#: 300 ms at 1 kHz is 300 samples).
MAX_PENDING = 1024

class Part:
    """One source's message in a pending sample: its ``values``, its source timestamp
    ``src_ns`` (None: unknown), the latest channel received when it arrived and ``arrival``, the
    number of channel messages received before it."""

    __slots__ = ("arrival", "arrival_channel", "src_ns", "values")

    def __init__(self, values: np.ndarray, src_ns: int | None, arrival_channel: int, arrival: int = 0):
        self.values = values
        self.src_ns = src_ns
        self.arrival_channel = arrival_channel
        self.arrival = arrival


class Pending:
    """One sample being assembled: the parts that have arrived for one stamp, by source index,
    ``since``, the monotonic time its first part arrived, and ``changes``, a count of the parts set
    and dropped (a part replaced counts: what is kept per sample compares it, :meth:`drop`)."""

    __slots__ = ("parts", "since", "stamp_ns", "changes")

    def __init__(self, stamp_ns: int, since: float):
        self.stamp_ns = stamp_ns
        self.parts: dict[int, Part] = {}
        self.since = since
        self.changes = 0

    def drop(self, index: int) -> None:
        """Remove source ``index``'s part."""
        del self.parts[index]
        self.changes += 1


class Pairing:
    """The pending samples by stamp, and the rule that says when one is due.

    ``upto`` is the newest stamp of a complete sample: an older sample will not be completed
    any more and is due with the parts it has.
    """

    def __init__(self, sources: tuple[Source, ...], p: tuple[int, ...], tolerance_ns: int = 0):
        self.sources = sources
        self.tol = int(tolerance_ns)
        self._p = p
        # the sources every sample of channel c needs (its own and the shared ones)
        self._required = tuple(frozenset(s.index for s in sources if s.channel in (None, c))
                               for c in range(1, len(p) + 1))
        self._reads: dict[tuple, tuple] = {}     # (parts' sources, channel) -> measurement's order and rows
        self.pending: dict[int, Pending] = {}
        self.upto = -1

    def add(self, index: int, stamp_ns: int, values: np.ndarray, src_ns: int | None, arrival_channel: int,
            now_mono: float, arrival: int = 0) -> Pending:
        """Add source ``index``'s part to the sample at ``stamp_ns`` (a new one waits from ``now_mono``;
        ``arrival``: the channel messages received before it)."""
        pend = self.pending.get(stamp_ns)
        if pend is None and self.tol:
            pend = self._near(index, stamp_ns)
        if pend is None:
            pend = self.pending[stamp_ns] = Pending(stamp_ns, now_mono)
        pend.parts[index] = Part(values, None if src_ns is None else int(src_ns), arrival_channel, arrival)
        pend.changes += 1
        return pend

    def _near(self, index: int, stamp_ns: int) -> Pending | None:
        """The pending sample stamped nearest ``stamp_ns`` within the tolerance that lacks source
        ``index`` (None: none); re-stamped with ``stamp_ns`` when the part is the first
        channel-specific one."""
        near = [p for s, p in self.pending.items() if abs(s - stamp_ns) <= self.tol and index not in p.parts]
        if not near:
            return None
        pend = min(near, key=lambda p: abs(p.stamp_ns - stamp_ns))
        if not self.sources[index].shared and all(self.sources[i].shared for i in pend.parts) \
                and stamp_ns not in self.pending:
            del self.pending[pend.stamp_ns]
            pend.stamp_ns = stamp_ns
            self.pending[stamp_ns] = pend
        return pend

    def complete(self, pend: Pending, channel: int) -> bool:
        """Whether every source that a sample of ``channel`` needs has arrived."""
        return pend.parts.keys() >= self._required[channel - 1]

    def settle(self, stamp_ns: int) -> None:
        """A sample at ``stamp_ns`` is complete: older ones go with the parts they have."""
        self.upto = max(self.upto, stamp_ns)

    def due(self, pend: Pending, channel: int, now_mono: float, timeout: float | None) -> bool:
        """Whether a sample of ``channel`` is answered now: complete, superseded by a newer complete
        one, or waiting longer than ``timeout`` (s; None: no timeout)."""
        return (pend.stamp_ns <= self.upto or self.complete(pend, channel)
                or (timeout is not None and now_mono - pend.since > timeout))

    def overflow(self) -> Iterator[int]:
        """The stamps to answer now because more than :data:`MAX_PENDING` samples wait (oldest first)."""
        while len(self.pending) > MAX_PENDING:
            yield min(self.pending)

    def oldest(self) -> Pending | None:
        """The pending sample with the oldest stamp (None: none waits)."""
        return self.pending[min(self.pending)] if self.pending else None

    def pop(self, stamp_ns: int) -> Pending | None:
        """Take the sample at ``stamp_ns`` out (None: none)."""
        return self.pending.pop(stamp_ns, None)

    def clear(self) -> int:
        """Forget every pending sample; returns the number of parts dropped."""
        n = sum(len(p.parts) for p in self.pending.values())
        self.pending = {}
        self.upto = -1
        return n

    def topic(self, pend: Pending) -> str:
        """The topic a rejection of the whole sample is counted under: its first part of a
        channel-specific source, else its first part's."""
        return next((self.sources[i].topic for i in pend.parts if not self.sources[i].shared),
                    self.sources[next(iter(pend.parts))].topic)

    def measurement(self, pend: Pending, channel: int) -> Measurement:
        """The sample read as ``channel``: its parts' values in row order (rows None: all of them).
        The order and the rows depend on the parts' sources and the channel only: found once for each."""
        parts = pend.parts
        key = (*parts, channel)
        read = self._reads.get(key)
        if read is None:
            rows: list[int] = []
            for i in parts:
                rows.extend(self.sources[i].rows[channel - 1])
            order = sorted(range(len(rows)), key=rows.__getitem__)
            r = tuple(rows[k] for k in order)
            read = self._reads[key] = (order, None if r == tuple(range(self._p[channel - 1])) else r)
        vals: list[float] = []
        for part in parts.values():
            vals.extend(part.values.tolist())
        order, r = read
        return Measurement(pend.stamp_ns, channel, r, np.array([vals[k] for k in order], dtype=float))


class DeadTime:
    """The dead time after a switch (module docstring): ``dead_ns`` (0: none); ``shared0`` the
    index of the first shared source (whose stamps give the period)."""

    def __init__(self, dead_ns: int, shared0: int | None):
        self.dead_ns = dead_ns
        self.shared0 = shared0
        self.period_ns = 0              # the latest gap between accepted shared-rows stamps
        self.first_ns: int | None = None   # first shared-rows stamp after a channel change
        self.channel_part = False       # a channel-specific part accepted since the change

    def switched(self) -> None:
        """The channel changed (or the estimator reset): a new dead time may start."""
        self.first_ns = None
        self.channel_part = False

    def accepted(self, src: Source, stamp_ns: int, last_ns: int | None) -> None:
        """A part of ``src`` at ``stamp_ns`` was accepted (``last_ns``: the source's previous stamp)."""
        if src.index == self.shared0 and last_ns is not None:
            self.period_ns = stamp_ns - last_ns
        elif not src.shared:
            self.channel_part = True

    def certainly_blind(self, stamp_ns: int) -> bool:
        """Whether a shared-rows sample at ``stamp_ns`` lies in the dead time for sure."""
        if not self.dead_ns or self.channel_part:
            return False
        if self.first_ns is None:
            self.first_ns = stamp_ns
        return stamp_ns - self.first_ns < self.dead_ns - self.period_ns
