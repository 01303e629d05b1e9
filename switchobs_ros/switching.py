"""Attribution by stamps: the switching instants of stamped channel messages.

A ``switchobs_msgs/ActiveChannel`` carries the switching instant in its header stamp, on the
sensor's clock: ``channel`` holds from that instant on. A sample is attributed by comparing its
header stamp with the switching instants (both sensor stamps), never by the middleware's source
timestamps of two computers against each other: the sample at stamp ``s`` is on the channel of
the latest instant ``S <= s``. Clocks of different computers disagree by up to the declared
tolerance ``d`` (``clock_tolerance_ms``), so a sample with ``|s - S| <= d`` for a switching
instant ``S`` is *ambiguous* (:attr:`~switchobs_ros.attribution.Verdict.NEAR_SWITCH`): the
pipeline uses it only where the consistency test names exactly one channel, else drops its
channel rows and counts them.

A sample is *certain* once a later switching instant ``S > s + d`` is known, or a channel message
sent ``2 d`` after it (source timestamps: a switch is published when it happens, so none before
``s + d`` can follow it), or at once when it lies within the *horizon* after the latest switching
instant (:attr:`SwitchHistory.horizon`: the parameter ``switch_horizon``, 0.9 by default, of the
shortest residence of its channel the gains were designed for, less ``d``): no switch can come
sooner while the schedule holds, and a switch that does come sooner arrives as a switching message
for samples already answered, which withdraws the bounds (:meth:`SwitchHistory.remember`).
Nothing else makes a sample certain: a sample whose reorder window passes before the stamps prove
its channel is *uncertain*
(:attr:`~switchobs_ros.attribution.Verdict.UNCERTAIN`), never attributed by a guess; the pipeline
treats it as ambiguous. A gap in the publisher's sequence numbers between two messages with
different instants leaves the channel between them unknown
(:attr:`~switchobs_ros.attribution.Verdict.LOST`): from the horizon after the earlier instant on (no
switch comes sooner while the schedule holds), for the samples not sent ``2 d`` before the last
message received ahead of the gap (that message proves their channel); a repeated message (same
instant and channel) makes a lost repetition harmless. As every answered sample's channel was
proven, a gap found later never concerns an answer.
"""

from __future__ import annotations

import bisect

__all__ = ["SwitchHistory"]

#: Switching instants remembered.
HISTORY = 256


class SwitchHistory:
    """The switching instants received (module docstring), ``tolerance_ns`` the clock tolerance.

    ``horizon`` (per channel, ns): how long after its switching instant a sample is certain at
    once; ``late`` counts the switching messages that arrived after samples they govern were
    answered, ``lost_messages`` those missing across a change of instant; ``lost`` holds the
    intervals ``(from, to, sent)`` of unknown channel, ``sent`` the source timestamp of the last
    message received ahead of the gap (None: unknown).
    """

    def __init__(self, tolerance_ns: int):
        self.tol = int(tolerance_ns)
        self.horizon: dict[int, int] = {}   # per channel: certain at once up to this after its instant (ns)
        self.at: list[int] = []         # switching instants (sorted)
        self.ch: list[int] = []         # the channel from each instant on
        self.lost: list[tuple[int, int, int | None]] = []   # (from, to, sent): channel unknown in between
        self.latest_src: int | None = None        # newest source timestamp of a channel message
        self._last: tuple[int, int | None] | None = None   # (instant, seq) of the newest message
        self.answered = -1                        # newest stamp of a sample answered on a proven channel
        self.late = 0
        self.lost_messages = 0
        self.received = 0                         # switching messages received

    def __bool__(self) -> bool:
        return bool(self.at)

    def remember(self, switch_ns: int, channel: int, src_ns: int | None, seq: int | None, lost: int) -> list[str]:
        """A stamped channel message: ``channel`` from ``switch_ns`` on, sent at ``src_ns``;
        ``lost`` the messages of its publisher missing before it (sequence numbers). Returns why
        the bounds must be withdrawn (empty: they need not): a change of channel at or before a
        sample already answered (its proof failed: the schedule or the clock tolerance broken)."""
        why = []
        self.received += 1
        before_src = self.latest_src
        if src_ns is not None:
            self.latest_src = src_ns if self.latest_src is None else max(self.latest_src, src_ns)
        if lost and self._last is not None and self._last[0] != switch_ns:
            self.lost_messages += lost
            lo, hi = sorted((self._last[0], switch_ns))
            j = bisect.bisect_right(self.at, lo) - 1      # no switch within the horizon of the one before
            if j >= 0 and self.at[j] == lo:
                lo = min(hi, lo + self.horizon.get(self.ch[j], 0))
            self.lost.append((lo, hi, before_src))
            del self.lost[:-HISTORY]
        self._last = (switch_ns, seq)
        k = bisect.bisect_left(self.at, switch_ns)
        if k < len(self.at) and self.at[k] == switch_ns:
            if self.ch[k] == channel:
                return why          # a repetition
            self.ch[k] = channel
        else:
            self.at.insert(k, switch_ns)
            self.ch.insert(k, channel)
        before = self.ch[k - 1] if k else 0
        if self.answered >= switch_ns - self.tol and before != channel:
            self.late += 1
            why.append(f"a switching message (channel {channel} from stamp {switch_ns}) arrived after samples it "
                       "governs were answered on the channel before it (a residence shorter than the schedule's, or "
                       "stamps beyond clock_tolerance_ms)")
        if len(self.at) > HISTORY:
            del self.at[0], self.ch[0]
        return why

    def resolve(self, stamp_ns: int, src_ns: int | None, complete: bool = False) -> tuple[str, int, bool]:
        """``(verdict, channel, certain)`` of a sample at header stamp ``stamp_ns`` (sent at
        ``src_ns``; ``complete``: a channel message sent after it has arrived, by the order of a
        recording, or no channel message is still to come, the end of a recording).
        ``verdict`` is ``"channel"``, ``"near_switch"`` (``channel``: the one by the stamps as they
        are), ``"lost"`` or ``"none"`` (no switching instant before it); ``certain`` False: the
        stamps do not prove the channel yet (module docstring)."""
        k = bisect.bisect_right(self.at, stamp_ns) - 1
        nxt = self.at[k + 1] if k + 1 < len(self.at) else None
        certain = complete or (nxt is not None and nxt > stamp_ns + self.tol) \
            or self._sent_before(src_ns, self.latest_src) \
            or (nxt is None and k >= 0 and stamp_ns < self.at[k] + self.horizon.get(self.ch[k], 0) - self.tol)
        near = (k >= 0 and stamp_ns - self.at[k] <= self.tol) or (nxt is not None and nxt - stamp_ns <= self.tol)
        if near and self.tol:
            return "near_switch", self.ch[k] if k >= 0 else 0, True
        if any(lo <= stamp_ns < hi and not self._sent_before(src_ns, sent) for lo, hi, sent in self.lost):
            return "lost", 0, True
        if k < 0:
            return "none", 0, certain
        return "channel", self.ch[k], certain

    def _sent_before(self, src_ns: int | None, msg_src: int | None) -> bool:
        """Whether a sample sent at ``src_ns`` was sent more than ``2 d`` before a channel message sent at
        ``msg_src`` (which then proves its channel)."""
        return src_ns is not None and msg_src is not None and msg_src > src_ns + 2 * self.tol

    def answered_at(self, stamp_ns: int) -> None:
        """A sample at ``stamp_ns`` was answered on a channel the stamps proved (a later switching
        message that contradicts it withdraws the bounds)."""
        self.answered = max(self.answered, stamp_ns)
