"""The order of :func:`switchobs_ros.bag.order.order_messages`, computed while the recording is read.

The rules are those of :mod:`switchobs_ros.bag.order` (its docstring); the messages come in log-time
order, ties in the file's order (:meth:`switchobs_ros.bag.io.BagIn.log_order`). Most rules look at
one tie and at what came before it. Two look further ahead:

* a change of the channel compares the newest evidence logged before it with the *oldest evidence
  logged after it*, anywhere in the rest of the recording (so does a tie that proves no order);
* a channel-dependent part is unordered when its stamp lies in an interval found *anywhere* in the
  recording, before or after the part.

Each topic's evidence rises along the log order, so the oldest evidence after a place is the
smallest of each topic's next one. The stream keeps a window of ``W`` nanoseconds of log time:

* a tie is ordered once the recording has been read more than ``W`` past its log time;
* its messages are handed on once the ordering has passed ``W`` beyond them, with the intervals
  found meanwhile applied.

Within the window the result is :func:`order_messages`' exactly. A difference can only come from
a message logged more than about ``W`` minus the future tolerance after its own stamp (a recording
that delivered a message that late), or from a channel-dependent part whose stamp is no evidence
(beyond the future tolerance, or not newer than its topic's last) inside an interval found after
the part was handed on. Both are detected, never passed over: :class:`BeyondWindow` is raised, and
the caller orders the whole recording instead (``switchobs_bag estimate`` runs again with
:func:`order_messages`). So the order handed on is always :func:`order_messages`' order.

Memory: the messages of about ``2 W`` of log time, the intervals found (one per contradiction of
the log order by the stamps), and the stamps of channel-dependent parts handed on that are no
evidence (at most :data:`MAX_ODD_STAMPS`; beyond, :class:`BeyondWindow`).
"""

from __future__ import annotations

import bisect
from collections import deque
from collections.abc import Iterable, Iterator
from dataclasses import dataclass

__all__ = ["BeyondWindow", "MAX_ODD_STAMPS", "StreamCounts", "WINDOW_NS", "stream_order"]

#: The window (log time): 5 s. A recorder delivers a message milliseconds after its stamp; the
#: estimator waits 50 ms (its reorder window) for a channel to become certain. A message logged 5 s
#: after its stamp, or a tie spread that far, is an anomaly of the recording: it is detected and the
#: whole recording is ordered instead. At 32 agents and 50 Hz, 10 s of messages are about 3 MB.
WINDOW_NS = 5_000_000_000

#: Channel-dependent stamps kept that are no evidence, handed on and not unordered (beyond: BeyondWindow).
MAX_ODD_STAMPS = 100_000

_INF = 2**63


class BeyondWindow(Exception):
    """The order of the recording depends on messages further apart than the window (see the module
    docstring): order the whole recording (:func:`switchobs_ros.bag.order.order_messages`)."""


@dataclass
class StreamCounts:
    """``unordered``: parts handed on as unordered; ``unproven``: ties whose file order the stamps contradict."""

    unordered: int = 0
    unproven: int = 0


def stream_order(records: Iterable[tuple], future_ns: int, counts: StreamCounts,
                 window_ns: int = WINDOW_NS) -> Iterator[tuple[object, bool]]:
    """``(payload, unordered)`` in the order of :func:`order_messages`, with its unordered parts.

    ``records``: per message, in log-time order (ties in the file's order), ``(log_ns, topic, stamp,
    dependent, channel, is_channel, payload)`` with the meanings of :func:`order_messages`'
    arguments (``topic`` for :func:`switchobs_ros.bag.order.evidence`, whose ``future_ns`` is
    ``future_ns``). Raises :class:`BeyondWindow` (module docstring).
    """
    pending: deque = deque()       # read, not ordered: [log, topic, stamp, ev, dep, chan, is_chan, payload, flag]
    ready: deque = deque()         # ordered, not handed on: the same lists, flag = unordered in its tie
    nexts: dict[str, deque] = {}   # per topic: the evidence of its pending messages, in order
    last: dict[str, int] = {}      # per topic: its newest evidence (evidence())
    starts: list[int] = []         # merged intervals of unordered stamps (closed), sorted
    ends: list[int] = []
    odd: list[int] = []            # sorted: dependent stamps handed on, not unordered, that are no evidence
    state = {"before": -1, "current": None, "unknown": False, "threshold": -1, "handed": -1}

    def inside(s: int) -> bool:
        j = bisect.bisect_right(starts, s) - 1
        return j >= 0 and s <= ends[j]

    def add_interval(a: int, b: int) -> None:
        # a stamp already handed on in [a, b] would be unordered in the whole recording's order
        if state["handed"] >= a or bisect.bisect_left(odd, a) < bisect.bisect_right(odd, b):
            raise BeyondWindow(f"an interval [{a}, {b}] found after parts in it were handed on")
        j = bisect.bisect_left(starts, a)
        starts.insert(j, a)
        ends.insert(j, b)
        ms: list[int] = []
        me: list[int] = []
        for x, y in zip(starts, ends):
            if ms and x <= me[-1]:
                me[-1] = max(me[-1], y)
            else:
                ms.append(x)
                me.append(y)
        starts[:], ends[:] = ms, me

    def oldest_after() -> int:
        return min((d[0] for d in nexts.values() if d), default=_INF)

    def passed(r: list) -> None:
        """``r`` leaves the pending messages: its evidence is no longer ahead."""
        if r[3] is not None:
            nexts[r[1]].popleft()

    def order_tie() -> None:
        log = pending[0][0]
        group = []
        while pending and pending[0][0] == log:
            group.append(pending.popleft())
        stamps = [r[2] for r in group if r[2] is not None]
        if all(a <= b for a, b in zip(stamps, stamps[1:])):          # the file's order, confirmed by the stamps
            for r in group:
                passed(r)
                c = r[5]
                if c is not None:
                    if c != state["current"]:
                        after = oldest_after()
                        before = state["before"]
                        state["threshold"] = max(state["threshold"], min(before, after))
                        if before > after:
                            add_interval(after, before)
                    state["current"], state["unknown"] = c, False
                elif state["unknown"] and r[4]:
                    r[8] = True
                if r[3] is not None:
                    state["before"] = max(state["before"], r[3])
                ready.append(r)
            return
        counts.unproven += 1                                          # no order proven: by stamp
        for r in group:
            passed(r)
        lo, hi = state["before"], oldest_after()
        values = {r[5] for r in group if r[5] is not None}
        chans = [r for r in group if r[6]]
        stamped = sorted((r for r in group if r[2] is not None), key=lambda r: r[2])     # stable: file order
        rest = [r for r in group if r[2] is None and not r[6]]
        cut = bisect.bisect_right([r[2] for r in stamped], lo)
        if values and len(values | {state["current"]}) > 1:
            state["threshold"] = max(state["threshold"], hi)
            for r in stamped:
                if r[4] and lo <= r[2] <= hi:
                    r[8] = True
            if lo > hi:
                add_interval(hi, lo)
        if state["unknown"]:
            for r in (stamped[:cut] if values else stamped):
                if r[4]:
                    r[8] = True
        ready.extend(stamped[:cut])
        ready.extend(chans)
        ready.extend(stamped[cut:])
        ready.extend(rest)
        for r in group:
            if r[3] is not None:
                state["before"] = max(state["before"], r[3])
        if values:
            state["current"] = next(r[5] for r in reversed(chans) if r[5] is not None)
            state["unknown"] = len(values) > 1

    def hand_on(r: list) -> tuple[object, bool]:
        s = r[2]
        flag = r[8]
        if r[4] and s is not None:
            if not flag and starts and inside(s):
                flag = True
            if not flag:
                if r[3] is not None:
                    if s > state["handed"]:
                        state["handed"] = s
                else:
                    bisect.insort(odd, s)
                    if len(odd) > MAX_ODD_STAMPS:
                        raise BeyondWindow(f"more than {MAX_ODD_STAMPS} channel-dependent stamps that are no evidence")
        if flag:
            counts.unordered += 1
        return r[7], flag

    for log, topic, stamp, dep, chan, is_chan, payload in records:
        ev = None
        if stamp is not None and 0 < stamp <= log + future_ns and stamp > last.get(topic, 0):
            last[topic] = ev = stamp
            if ev < state["threshold"]:
                raise BeyondWindow(f"evidence {ev} logged at {log}, older than the evidence of an order made "
                                   f"{window_ns} ns before")
            d = nexts.get(topic)
            if d is None:
                d = nexts[topic] = deque()
            d.append(ev)
        pending.append([log, topic, stamp, ev, dep, chan, is_chan, payload, False])
        while pending[0][0] + window_ns < log:
            order_tie()
            ordered = ready[-1][0]
            while ready[0][0] + window_ns < ordered:
                yield hand_on(ready.popleft())
    while pending:
        order_tie()
    while ready:
        yield hand_on(ready.popleft())
