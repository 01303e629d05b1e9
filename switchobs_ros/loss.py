"""Messages that never reached the estimator, counted per input topic from the publishers' numbers.

rclpy's ``MessageInfo`` carries each message's ``publication_sequence_number``: a publisher numbers
the messages it sends 1, 2, 3, ... A gap between two numbers of one publisher is messages it sent
that never arrived: dropped by best-effort transport, or overwritten in a full subscription queue
under a flood. The channel topic's gaps also decide attribution (:mod:`switchobs_ros.attribution`);
here every input topic's are counted, so that nothing is lost silently (``/diagnostics``: ``<topic>
lost``).

rclpy does not say which publisher sent a message, so a topic's numbers are followed as up to
:data:`MAX_SEQUENCES` sequences: a number extends the sequence whose last number is the largest
below it (so a second publisher's messages are no gap in the first one's), and the numbers skipped
are lost. A number at or below the last of every sequence starts a new sequence: a restarted or
another publisher (``<topic> publisher restarts``), whose numbers before it are not counted (it may
have sent them before this node subscribed). Without sequence numbers (the rmw gives none, or an
offline bag) nothing is counted. A publisher of another message type on an input topic delivers
nothing at all: the node finds it in the ROS graph (``<topic> publishers of another type``).
"""

from __future__ import annotations

from collections import Counter
from typing import Any

from .attribution import sequence

__all__ = ["MAX_SEQUENCES", "SequenceLoss"]

#: Sequences (publishers) followed per topic; the one extended least recently is dropped beyond it.
MAX_SEQUENCES = 8


class SequenceLoss:
    """Lost messages and new sequences per topic (module docstring): ``lost[topic]``, ``restarts[topic]``."""

    def __init__(self) -> None:
        self.lost: Counter = Counter()
        self.restarts: Counter = Counter()
        self.wrong_type: Counter = Counter()         # publishers of another message type now (the graph)
        self.wrong_type_names: dict[str, str] = {}
        self._seqs: dict[str, list[list[int]]] = {}     # per topic: [last number, when last extended]
        self._clock = 0

    def seen(self, topic: str, seq: Any) -> int:
        """A message of ``topic`` with publication sequence number ``seq`` arrived; returns the
        messages found lost before it (0 when ``seq`` is unknown)."""
        s = sequence(seq)
        if s is None:
            return 0
        self._clock += 1
        seqs = self._seqs.get(topic)
        if seqs is None:
            seqs = self._seqs[topic] = []
        if len(seqs) == 1:                         # one publisher (the common case): no search
            q = seqs[0] if seqs[0][0] < s else None
        else:                                      # the sequence whose last number is nearest below
            below = [q for q in seqs if q[0] < s]
            q = max(below, key=lambda q: q[0]) if below else None
        if q is not None:                          # extends it
            lost = s - q[0] - 1
            q[0], q[1] = s, self._clock
            self.lost[topic] += lost
            return lost
        if seqs:
            self.restarts[topic] += 1
        if len(seqs) >= MAX_SEQUENCES:
            seqs.remove(min(seqs, key=lambda q: q[1]))
        seqs.append([s, self._clock])
        return 0

    def wrong_type_seen(self, topic: str, count: int, names: str) -> bool:
        """``count`` publishers of another message type (``names``) are on ``topic`` now (the ROS
        graph): none of their messages reach the estimator. True when that changed."""
        changed = (self.wrong_type[topic], self.wrong_type_names.get(topic, "")) != (count, names)
        self.wrong_type[topic] = int(count)
        self.wrong_type_names[topic] = names
        return changed
