"""Clocks measured: each source's stamps against the estimator's receive clock.

A message stamped ``s`` (its header stamp, on its sender's clock) and received at ``r`` (the
estimator's node clock) has ``r - s`` = latency - offset, where offset is how far the sender's
clock is ahead. The latency is never negative, so ``min(r - s)`` over the messages is an upper
bound of minus the offset: a negative minimum proves the sender's clock ahead by at least its
magnitude. :class:`ClockWatch` keeps that minimum per source (the recent window's and the whole
run's) for diagnostics, and says when it proves an offset beyond the declared tolerance
(``clock_tolerance_ms``): the bounds assume every stamp within it, so they are withdrawn with the
source and the offset named. An offset behind (a positive one) looks like latency and cannot be
proven from the stamps alone; the tolerance is the sender's declaration for it.

The middleware's source timestamps (the sender's system clock) against the receive timestamps
(ours) are checked even with a tolerance of 0, which declares one computer: there both are one
clock and a receive never precedes its send, so a negative latency beyond :data:`SYSTEM_MARGIN_NS`
proves another computer whose clock runs ahead (sim time and test stamps do not enter these).
"""

from __future__ import annotations

from collections import deque

__all__ = ["ClockWatch"]

#: Messages per source in the recent window.
WINDOW = 200
#: With a tolerance of 0: how far a system-clock source timestamp may lead its receive timestamp
#: before it proves another computer's clock ahead (a step of this computer's clock aside).
SYSTEM_MARGIN_NS = 1_000_000


class ClockWatch:
    """The minimum of ``receive - stamp`` per source (module docstring); ``tolerance_ns`` the
    declared clock tolerance. ``check``: whether an offset beyond it withdraws the bounds (default:
    with a tolerance. A tolerance of 0 declares every stamp on the estimator's own clock and is not
    checked: under sim time or in a recording the receive clock lags the stamps by a tick of
    ``/clock``, and test and bench publishers stamp bursts ahead of it)."""

    def __init__(self, tolerance_ns: int, check: bool | None = None):
        self.tol = int(tolerance_ns)
        self.check = self.tol > 0 if check is None else bool(check)
        self._recent: dict[str, deque] = {}
        self.least: dict[str, int] = {}        # over the whole run
        self.skewed: dict[str, int] = {}       # sources whose stamps proved an offset beyond the tolerance

    def seen(self, topic: str, stamp_ns: int, now_ns: int, system: bool = False) -> str:
        """A message of ``topic`` stamped ``stamp_ns`` received at ``now_ns``; returns why the
        bounds must be withdrawn ('' : they need not). ``system``: both are system-clock
        timestamps of the middleware (checked with a tolerance of 0 too, module docstring)."""
        lat = int(now_ns) - int(stamp_ns)
        q = self._recent.get(topic)
        if q is None:
            q = self._recent[topic] = deque(maxlen=WINDOW)
        q.append(lat)
        if lat < self.least.get(topic, lat + 1):
            self.least[topic] = lat
        if (self.check and -lat > self.tol) or (system and not self.check and -lat > SYSTEM_MARGIN_NS):
            first = topic not in self.skewed
            self.skewed[topic] = max(self.skewed.get(topic, 0), -lat)
            if first:
                return (f"clock offset: {topic}'s stamps are {-lat * 1e-6:.3f} ms ahead of the estimator's clock "
                        f"(a negative latency), beyond clock_tolerance_ms = {self.tol * 1e-6:g}"
                        + ("" if self.check else " (0: one computer declared; declare the clocks' tolerance)"))
        return ""

    def offsets_ms(self) -> dict[str, float]:
        """Per source, the recent window's minimum of ``receive - stamp`` (ms): minus the offset
        plus the least latency; negative proves the source's clock ahead."""
        return {t: min(q) * 1e-6 for t, q in self._recent.items() if q}
