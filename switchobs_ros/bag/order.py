"""The order in which ``switchobs_bag estimate`` hands a recording to the estimator, and what the
recording cannot tell.

A bag gives each message its log time (when the recorder received it, on the recorder's clock) and
its place in the file (the order the recorder wrote it: the order it received them); the inputs
carry their own header stamps too. A channel message carries no stamp: where it was sent among the
poses is known only from the recording's order, so that order is evidence, checked, not truth:

* Messages are taken by log time, ties in the file's order (the recorder's), never by topic: a
  backlog written with one log time, or a clock that ticks coarsely, keeps the order it was
  received in.
* A tie (messages of one log time) whose stamped inputs are not in stamp order in the file (a
  recording rewritten or re-sorted) proves no order: its inputs are taken by stamp, its channel
  messages before those stamped after everything logged before the tie.
* Around every change of the channel, a channel-dependent part (a sample of a source whose channel
  comes from the channel topic: the paper's target pose) is *unordered* when the recording does
  not establish on which side of the change it was sent: in an unproven tie, when its stamp is not
  older than every stamp logged before the tie and not newer than every stamp logged after it; and
  anywhere, when the stamps logged before the change are newer than some logged after it (the log
  order contradicts the stamps there) and its stamp lies between them. After an unproven tie whose
  channel messages disagree, the channel is unknown until the next channel message.

Unordered parts are rejected (``ambiguous_channel``) and counted, never attributed by a guess; the
shared parts of their samples (the camera's pose) are used alone. The stamps taken as evidence are
those the estimator could accept: a valid time, not beyond the log time plus the future tolerance,
newer than the previous one of the same topic.
"""

from __future__ import annotations

import bisect
from collections.abc import Sequence
from dataclasses import dataclass

__all__ = ["Ordering", "evidence", "order_messages"]


@dataclass(frozen=True)
class Ordering:
    """``order``: indices of the messages in the order to process them; ``unordered``: indices of
    the channel-dependent parts whose side of a channel change the recording does not establish;
    ``unproven``: ties whose file order the stamps contradict."""

    order: list[int]
    unordered: frozenset[int]
    unproven: int


def order_messages(log_ns: Sequence[int], stamp: Sequence[int | None], evidence: Sequence[int | None],
                   dependent: Sequence[bool], channel: Sequence[int | None],
                   is_channel: Sequence[bool]) -> Ordering:
    """The processing order and the unordered parts of a recording (module docstring).

    Per message, in file order: its log time; ``stamp``: the header stamp of an input, if a valid
    time (else None); ``evidence``: that stamp where it is evidence (:func:`evidence`; else None);
    ``dependent``: a part attributed by the channel topic; ``channel``: the value of a valid
    channel message (else None); ``is_channel``: a message of the channel topic (valid or not).
    """
    n = len(log_ns)
    seq = sorted(range(n), key=log_ns.__getitem__)            # stable: ties in the file's order
    # evidence along seq: the newest stamp before each place, the oldest from each place on
    before = [-1] * (n + 1)
    for k, i in enumerate(seq):
        s = evidence[i]
        before[k + 1] = before[k] if s is None else max(before[k], s)
    after = [2**63] * (n + 1)
    for k in range(n - 1, -1, -1):
        s = evidence[seq[k]]
        after[k] = after[k + 1] if s is None else min(after[k + 1], s)
    order: list[int] = []
    intervals: list[tuple[int, int]] = []        # stamps of dependent parts unordered wherever they are
    unordered: set[int] = set()
    unproven = 0
    current: int | None = None                   # the channel in effect (processing order)
    unknown = False                              # the channel is unknown until the next channel message
    k = 0
    while k < n:
        end = k + 1
        while end < n and log_ns[seq[end]] == log_ns[seq[k]]:
            end += 1
        group = seq[k:end]
        stamps = [stamp[i] for i in group if stamp[i] is not None]
        if all(a <= b for a, b in zip(stamps, stamps[1:])):       # the file's order, confirmed by the stamps
            for pos, i in enumerate(group, start=k):
                c = channel[i]
                if c is not None:
                    if c != current and before[pos] > after[pos + 1]:
                        intervals.append((after[pos + 1], before[pos]))
                    current, unknown = c, False
                elif unknown and dependent[i]:
                    unordered.add(i)
                order.append(i)
        else:                                                     # no order proven: by stamp
            unproven += 1
            lo, hi = before[k], after[end]
            values = {channel[i] for i in group if channel[i] is not None}
            chans = [i for i in group if is_channel[i]]
            stamped = sorted((i for i in group if stamp[i] is not None), key=lambda i: (stamp[i], i))
            rest = [i for i in group if stamp[i] is None and not is_channel[i]]
            cut = bisect.bisect_right([stamp[i] for i in stamped], lo)
            if values and len(values | {current}) > 1:            # the channel changes somewhere in the tie
                unordered.update(i for i in stamped if dependent[i] and lo <= stamp[i] <= hi)
                if lo > hi:
                    intervals.append((hi, lo))
            if unknown:                                           # what comes before the tie's channel messages
                unordered.update(i for i in (stamped[:cut] if values else stamped) if dependent[i])
            order.extend(stamped[:cut])
            order.extend(chans)
            order.extend(stamped[cut:])
            order.extend(rest)
            if values:
                current = next(channel[i] for i in reversed(chans) if channel[i] is not None)
                unknown = len(values) > 1
        k = end
    if intervals:
        intervals.sort()
        merged: list[list[int]] = []
        for a, b in intervals:
            if merged and a <= merged[-1][1]:
                merged[-1][1] = max(merged[-1][1], b)
            else:
                merged.append([a, b])
        starts = [a for a, _ in merged]
        for i in range(n):
            s = stamp[i]
            if dependent[i] and s is not None:
                j = bisect.bisect_right(starts, s) - 1
                if j >= 0 and s <= merged[j][1]:
                    unordered.add(i)
    return Ordering(order, frozenset(unordered), unproven)


def evidence(topics: Sequence[str], log_ns: Sequence[int], stamp: Sequence[int | None],
             future_ns: int) -> list[int | None]:
    """The stamps taken as evidence (module docstring), per message in file order: ``stamp[i]``
    (None: not an input, or no valid time) when it is not beyond ``log_ns[i] + future_ns`` and is
    newer than the previous evidence of the same topic (in log-time order, ties in file order)."""
    out: list[int | None] = [None] * len(topics)
    last: dict[str, int] = {}
    for i in sorted(range(len(topics)), key=log_ns.__getitem__):
        s = stamp[i]
        if s is None or s <= 0 or s > log_ns[i] + future_ns or s <= last.get(topics[i], 0):
            continue
        last[topics[i]] = s
        out[i] = s
    return out
