"""Channel attribution: the channel a sample was taken on, never guessed from arrival order.

A source of one channel names its channel. A source shared by several channels (the target pose
of the paper interface) takes the channel that was active when its message was *sent*: the latest
channel message whose source timestamp (the publisher's clock, rclpy's ``MessageInfo``) is not
after the sample's. DDS and the executor reorder messages of different topics under load, so a
sample waits, in a bounded reorder window, until its channel is certain: a channel message sent
after it has arrived (the channel topic is reliable and keeps its order), or the window has
passed. :meth:`ChannelAttribution.resolve` gives the :class:`Verdict`.

Lost channel messages: reliable keep-last delivery loses messages under load, so a later channel
message does not prove that none was sent in between; the publisher's sequence numbers
(``publication_sequence_number``) do. A sample sent between two received channel messages whose
numbers are not consecutive has an unknown channel (:attr:`Verdict.LOST`). A sequence that starts
again is a restarted publisher (DDS numbers a writer's messages from 1), not a gap; only its own
missing first messages are. Without sequence numbers the history is taken as complete.

A channel message that arrives after samples it governs were answered (a window too short for the
load), or a gap found after samples in it were answered on the window's expiry, means that an
answer may have used the wrong channel: :meth:`ChannelAttribution.remember` returns the reason, and
the pipeline withdraws the bounds.

Without source timestamps (a bag's messages in the order the recorder wrote them) the latest
channel received is the channel: that order is the publishing order.

Stamped channel messages (``switchobs_msgs/ActiveChannel``, the switching instant in the header
stamp) replace all of this by a comparison of sensor stamps (:mod:`switchobs_ros.switching`): once
one has arrived, a sample is attributed by its header stamp against the switching instants, within
the declared clock tolerance (:attr:`Verdict.NEAR_SWITCH`). There the window's expiry proves
nothing: a sample the stamps have not proven by then is :attr:`Verdict.UNCERTAIN`, which the
pipeline treats as ambiguous (named by the consistency test, or its channel rows dropped).
"""

from __future__ import annotations

import bisect
import enum
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import msg_bridge as mb
from msg_bridge import Reason, Rejection

from .pairing import Pending
from .sources import Source
from .switching import SwitchHistory

__all__ = ["CHANNEL_HISTORY", "ChannelAttribution", "Resolution", "Verdict", "lost_between", "sequence"]

#: Channel messages remembered for attribution by source timestamp.
CHANNEL_HISTORY = 256


class Verdict(enum.Enum):
    """What attribution says of a sample's channel."""

    #: The channel is known (:attr:`Resolution.channel`).
    CHANNEL = "channel"
    #: No channel was active when the sample was sent.
    NO_CHANNEL = "no_channel"
    #: Parts of one-channel sources of different channels share the sample's stamp.
    CONFLICT = "conflict"
    #: Not certain within the reorder window (or sent before the channel history kept).
    UNCERTAIN = "uncertain"
    #: Sent while channel messages were lost (a gap in the publisher's sequence numbers).
    LOST = "lost"
    #: Stamped within the clock tolerance of a switching instant (stamped channel messages).
    NEAR_SWITCH = "near_switch"

    @property
    def rejection(self) -> tuple[Reason, str]:
        """The reason and detail under which the parts of a sample with this verdict (not
        :attr:`CHANNEL`) are rejected."""
        return _REJECTIONS[self]


_REJECTIONS = {
    Verdict.NO_CHANNEL: (Reason.NO_CHANNEL, "no active channel when it was sent"),
    Verdict.CONFLICT: (Reason.AMBIGUOUS_CHANNEL, "parts from sources of different channels share one stamp"),
    Verdict.UNCERTAIN: (Reason.AMBIGUOUS_CHANNEL, "its channel was not certain within the reorder window"),
    Verdict.LOST: (Reason.AMBIGUOUS_CHANNEL,
                   "sent while channel messages were lost (a gap in the publisher's sequence numbers)"),
    Verdict.NEAR_SWITCH: (Reason.AMBIGUOUS_CHANNEL,
                          "stamped within clock_tolerance_ms of a switching instant (clocks of two computers)"),
}


@dataclass(frozen=True)
class Resolution:
    """A sample's :class:`Verdict`, its ``channel`` (1-based, with :attr:`Verdict.CHANNEL`) and
    whether that is ``certain`` (False: the sample waits in the reorder window)."""

    verdict: Verdict
    channel: int = 0
    certain: bool = True

    @classmethod
    def of(cls, channel: int, certain: bool = True) -> Resolution:
        """Channel ``channel``, or :attr:`Verdict.NO_CHANNEL` for 0 (none active). A resolution is
        immutable: one instance per Python ``int`` channel and ``certain`` serves every sample."""
        if type(channel) is not int:      # (a numpy integer keeps its own type, as given)
            return cls(Verdict.CHANNEL, channel, certain) if channel > 0 else cls(Verdict.NO_CHANNEL, 0, certain)
        got = _OF.get((channel, certain))
        if got is None:
            got = _OF[(channel, certain)] = cls(Verdict.CHANNEL, channel, certain) if channel > 0 \
                else cls(Verdict.NO_CHANNEL, 0, certain)
        return got


_OF: dict[tuple[int, bool], Resolution] = {}      # Resolution.of's instances


#: ``SwitchHistory.resolve``'s verdicts other than a channel.
_NAMED = {"near_switch": Verdict.NEAR_SWITCH, "lost": Verdict.LOST}


def lost_between(a: int | None, b: int | None) -> int:
    """Channel messages lost between two received ones with publication sequence numbers ``a``
    then ``b`` (None: unknown, nothing is assumed lost). A number that does not increase is a
    new publisher: only its own messages before ``b`` are missing, not the old one's after ``a``."""
    if a is None or b is None or b == a + 1:
        return 0
    return b - 1 if b <= a else b - a - 1


def sequence(seq: Any) -> int | None:
    """A publisher's sequence number as rclpy reports it, None when unknown (absent, 0, or the
    rmw's 'unsupported' value, UINT64_MAX)."""
    if seq is None:
        return None
    seq = int(seq)
    return seq if 0 < seq < 2**63 else None


class ChannelAttribution:
    """The history of channel messages and the verdicts it gives (module docstring).

    Parameters
    ----------
    sources : tuple of Source
        The input sources (:mod:`switchobs_ros.sources`).
    channel_topic : str or None
        The channel topic (None: every sample's channel comes from one-channel sources).
    window_ns : int
        The reorder window (0: none; arrival order decides before any channel message).

    ``channel`` is the latest channel received (arrival order); ``late`` counts channel messages
    that arrived after samples they govern were answered, ``lost`` the channel messages missing
    from the publisher's sequence.
    """

    def __init__(self, sources: tuple[Source, ...], channel_topic: str | None, window_ns: int,
                 tolerance_ns: int = 0):
        self.sources = sources
        self.stamped = SwitchHistory(tolerance_ns)    # switching instants (stamped channel messages)
        self._stamped_seq: int | None = None          # the newest stamped message's sequence number
        self.channel_topic = channel_topic
        self.window_ns = int(window_ns)
        self.channel = 0
        self.switch_ns: int | None = None    # newest channel-topic part stamp before the latest change
        self.late = 0
        self.lost = 0
        self._src: list[int] = []             # the history by source timestamp (sorted)
        self._val: list[int] = []
        self._seq: list[int | None] = []      # publication sequence numbers (None: unknown)
        self._truncated = False               # older entries dropped (CHANNEL_HISTORY)
        self._answered_src = -1               # newest source timestamp of an answered sample
        self._memo: tuple | None = None       # (sample, its key, verdict) of the last _by_stamps
        self._resolved: tuple | None = None   # (sample, its key, Resolution) of the last certain resolve by stamps
        self._fixed = any(s.channel is not None for s in sources)     # a source of one channel exists
        self._guessed_src = -1                # the same, of one answered on the window's expiry
        self._last_fixed = 0                  # channel of the latest sample from a one-channel source

    @property
    def sequence_numbers(self) -> tuple[int | None, ...]:
        """The publication sequence numbers of the history, by source timestamp."""
        return tuple(self._seq)

    # ------------------------------------------------------------------ channel messages
    def switch(self, channel: int, last_ns: Mapping[str, int | None]) -> None:
        """A valid channel message changed the latest channel (arrival order); ``last_ns``: the
        newest accepted stamp per topic (the parts up to the newest of the channel-topic sources'
        were taken while the previous channel was active)."""
        self.channel = channel
        stamps = [last_ns[s.topic] for s in self.sources if s.channel is None and not s.shared
                  and last_ns[s.topic] is not None]
        if stamps:
            self.switch_ns = max(stamps)

    def remember(self, src_ns: int, channel: int, seq: Any = None) -> list[str]:
        """Insert a channel message sent at ``src_ns`` (publication sequence number ``seq``) into
        the history. Returns why the bounds must be withdrawn (empty: they need not): the message
        changes the channel of samples already answered, or a gap in the sequence before it
        holds samples answered on the window's expiry."""
        seq = sequence(seq)
        why = []
        k = bisect.bisect_right(self._src, src_ns)
        if src_ns <= self._answered_src and (self._val[k - 1] if k else 0) != channel:
            self.late += 1
            why.append(f"a channel message (channel {channel}) arrived after samples it governs were answered "
                       "(raise reorder_window_ms)")
        lost = lost_between(self._seq[k - 1], seq) if k else 0
        if lost:
            self.lost += lost
            if self._guessed_src > self._src[k - 1]:
                why.append(f"channel messages were lost (publication sequence {self._seq[k - 1]} then {seq}) "
                           "around samples already answered: their channel is not certain")
        self._src.insert(k, src_ns)
        self._val.insert(k, channel)
        self._seq.insert(k, seq)
        if len(self._src) > CHANNEL_HISTORY:
            del self._src[0], self._val[0], self._seq[0]
            self._truncated = True
        return why

    def remember_switch(self, switch_ns: int, channel: int, src_ns: int | None, seq: Any = None) -> list[str]:
        """A stamped channel message: ``channel`` from the switching instant ``switch_ns`` on
        (:meth:`SwitchHistory.remember <switchobs_ros.switching.SwitchHistory.remember>`). Returns
        why the bounds must be withdrawn."""
        seq = sequence(seq)
        lost = lost_between(self._stamped_seq, seq) if self.stamped.at else 0
        self._stamped_seq = seq
        late0, lost0 = self.stamped.late, self.stamped.lost_messages
        why = self.stamped.remember(int(switch_ns), channel, src_ns, seq, lost)
        self.late += self.stamped.late - late0
        self.lost += self.stamped.lost_messages - lost0
        return why

    def remember_invalid(self, src_ns: int | None, seq: Any) -> list[str]:
        """A channel message with an invalid value: received, not lost, so with a sequence number
        it enters the history with the channel then active (:meth:`remember`)."""
        k = bisect.bisect_right(self._src, int(src_ns)) if src_ns is not None else 0
        if k and sequence(seq) is not None:
            return self.remember(int(src_ns), self._val[k - 1], seq)
        return []

    # ------------------------------------------------------------------ samples
    def refuse(self, src: Source, stamp_ns: int, src_ns: int | None, rej: Rejection | None) -> Rejection | None:
        """Why a part of ``src`` cannot be attributed, given the validation's ``rej`` (None: it can,
        or it waits for its channel): no channel received yet when arrival order decides (no
        source timestamp, or no reorder window), or, without source timestamps, stamped at or
        before the switch (taken while the previous channel was active)."""
        if self.stamped.at:     # by the sensors' stamps: neither arrival order nor the switch's camera stamp
            return rej
        if rej is None and src.channel is None and self.channel_topic and not self.channel \
                and (src_ns is None or not self.window_ns):
            rej = Rejection(Reason.NO_CHANNEL, self.channel_topic, "no active channel received yet")
        if not src.shared and src.channel is None and src_ns is None \
                and (rej is None or rej.reason in (Reason.OLD_STAMP, Reason.DUPLICATE_STAMP)):
            rej = mb.check_after_switch(stamp_ns, self.switch_ns) or rej   # the more specific reason
        return rej

    def resolve(self, pend: Pending, now_mono: float, force: bool = False) -> Resolution:
        """The channel of a pending sample and whether it is certain at ``now_mono`` (``force``:
        the window is over). By stamps, a certain answer is kept for the same sample, parts (set or
        replaced: ``Pending.changes``), switching messages received and ``force`` (:meth:`_by_stamps`): the
        pipeline asks again as it pairs, advances and answers a sample."""
        srcs = self.sources
        if self._fixed:
            fixed = {srcs[i].channel for i in pend.parts if srcs[i].channel is not None}
            if fixed:
                return Resolution.of(fixed.pop()) if len(fixed) == 1 else Resolution(Verdict.CONFLICT)
        if not self.channel_topic:          # shared rows only, one-channel sources elsewhere
            return Resolution.of(self._last_fixed)
        stamped = self.stamped
        if stamped.at:                      # by the sensors' stamps (switchobs_ros.switching)
            key = (pend.stamp_ns, pend.changes, stamped.received, force)
            got = self._resolved
            if got is not None and got[0] is pend and got[1] == key:
                return got[2]
            verdict, c, certain = self._by_stamps(pend, force)
            if verdict == "near_switch" and c and all(srcs[i].shared for i in pend.parts):
                verdict = "channel"     # shared rows read the same in every channel: they wait for a partner
            if not certain and self._expired(pend, now_mono):   # never a guess: ambiguous
                return Resolution(Verdict.NO_CHANNEL if verdict == "none" else Verdict.UNCERTAIN)
            if verdict == "channel":
                res = Resolution.of(c, certain)
            else:
                res = Resolution(_NAMED.get(verdict, Verdict.NO_CHANNEL), certain=certain)
            if certain:
                self._resolved = (pend, key, res)
            return res
        dep = [p for i, p in pend.parts.items() if not srcs[i].shared] or list(pend.parts.values())
        stamps = [p.src_ns for p in dep]
        if any(s is None for s in stamps) or not self._src:
            if self._src or not self.window_ns or any(s is None for s in stamps) or force:
                return Resolution.of(dep[0].arrival_channel or self.channel)
            # source timestamps but no channel message yet: wait for one (the window)
            return Resolution(Verdict.NO_CHANNEL, certain=self._expired(pend, now_mono))
        s = max(stamps)
        k = bisect.bisect_right(self._src, s) - 1
        certain = force or self._src[-1] > s or self._expired(pend, now_mono)
        if k < 0:
            return Resolution(Verdict.UNCERTAIN if self._truncated else Verdict.NO_CHANNEL, certain=certain)
        if k + 1 < len(self._src) and lost_between(self._seq[k], self._seq[k + 1]) > 0:
            return Resolution(Verdict.LOST)
        return Resolution.of(self._val[k], certain)

    def _by_stamps(self, pend: Pending, force: bool = False) -> tuple[str, int, bool]:
        """:meth:`SwitchHistory.resolve <switchobs_ros.switching.SwitchHistory.resolve>` for the
        sample; without source timestamps a switching message received after its parts proves
        its channel (the order of a recording is the publishing order).

        The answer depends on the sample (its stamp and parts) and on the switching messages
        received (every change of the history counts one in ``received``), so the last one is kept
        for the same sample, parts, count and ``force``: a sample is resolved, answered and
        recorded with one look-up."""
        key = (pend.stamp_ns, pend.changes, self.stamped.received, force)
        memo = self._memo
        if memo is not None and memo[0] is pend and memo[1] == key:
            return memo[2]
        sent = self._sent(pend)
        ordered = sent is None and self.stamped.received > max(p.arrival for p in pend.parts.values())
        out = self.stamped.resolve(pend.stamp_ns, sent, force or ordered)
        self._memo = (pend, key, out)
        return out

    def _sent(self, pend: Pending) -> int | None:
        """When the parts the sample's channel matters for were sent (the newest source timestamp of
        its channel parts, or of all when it has none; None: unknown)."""
        dep = [p for i, p in pend.parts.items() if not self.sources[i].shared] or list(pend.parts.values())
        src = [p.src_ns for p in dep]
        return None if None in src else max(src)

    def _expired(self, pend: Pending, now_mono: float) -> bool:
        return now_mono - pend.since >= self.window_ns * 1e-9

    def guessed(self, pend: Pending) -> bool:
        """Whether the history does not prove the channel of a sample that depends on it: no
        channel message sent after it has arrived (answered on the window's expiry)."""
        srcs = self.sources
        if self.stamped.at and self.channel_topic and not (self._fixed and any(srcs[i].channel is not None
                                                                                for i in pend.parts)):
            return not self._by_stamps(pend)[2]
        if not self.channel_topic or not self._src or all(srcs[i].shared for i in pend.parts) \
                or any(srcs[i].channel is not None for i in pend.parts):
            return False
        stamps = [p.src_ns for i, p in pend.parts.items() if not srcs[i].shared]
        return None not in stamps and self._src[-1] <= max(stamps)

    def read_as(self, pend: Pending, channel: int) -> None:
        """The sample is read as ``channel``: a sample of one-channel sources sets the channel of
        the shared rows that follow (no channel topic)."""
        if self.sources[next(iter(pend.parts))].channel is not None:
            self._last_fixed = channel

    def answered(self, pend: Pending, guessed: bool) -> None:
        """The sample was answered (``guessed``: on the window's expiry, :meth:`guessed`)."""
        if self.stamped.at:
            verdict, _, certain = self._by_stamps(pend)
            if certain and verdict == "channel":
                self.stamped.answered_at(pend.stamp_ns)     # on a channel the stamps proved
        srcs = [p.src_ns for p in pend.parts.values() if p.src_ns is not None]
        if srcs:
            newest = max(srcs)
            if newest > self._answered_src:
                self._answered_src = newest
            if guessed and newest > self._guessed_src:
                self._guessed_src = newest

    def reset(self) -> None:
        """The estimator reset: no switch is known for the parts that follow."""
        self.switch_ns = None
