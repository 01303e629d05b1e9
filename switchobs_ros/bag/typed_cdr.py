"""The typed bounds message (``switchobs_msgs/ErrorBounds``) as bytes without a message serialised per estimate.

:class:`ErrorBoundsBytes` takes the message :class:`msg_bridge.typed.ErrorBoundsWriter` fills (its rules
for the validity flags and the text stay there) and writes its bytes from a :class:`~switchobs_ros.bag.cdr.Template`
serialised once per validity flags and text (the only fields whose bytes are not a fixed layout:
``why_invalid`` is a string, and the flags change the text), patching the stamp, the three bounds and the
paper's envelope. The message it reads back is the writer's (``test/ros/test_bag_stream.py``).

The writer's message is filled once per set of the arguments its flags and text are made of (``valid``, ``why``,
``note``, and whether each bound is ``>= 0``): a later estimate with the same ones patches that template
directly (the stamp, the bounds and the envelope are the doubles given, written as the writer writes them),
without an rclpy message filled per estimate (``test_typed_cdr.py``: the bytes read back as the writer's
message over sequences of any such arguments).
"""

from __future__ import annotations

import copy
from collections.abc import Sequence

import numpy as np
from rclpy.serialization import serialize_message

from msg_bridge.cdr_padding import zero_padding
from msg_bridge.typed import ErrorBoundsWriter

from .cdr import Template

__all__ = ["ErrorBoundsBytes"]


class ErrorBoundsBytes:
    """``b.bytes(envelope_values, stamp_ns, valid, why, note)``: the serialised message of
    ``writer.msg(...)`` with the same arguments (:class:`~msg_bridge.typed.ErrorBoundsWriter`)."""

    #: Templates kept (one per validity flags and text; a re-certification's note is a new text).
    KEEP = 64

    def __init__(self, writer: ErrorBoundsWriter) -> None:
        self._w = writer
        self._kept: dict[tuple, Template | None] = {}
        self._given: dict[tuple, Template] = {}     # (valid, why, note, exact >= 0, noise >= 0) -> template

    def bytes(self, envelope_values: Sequence[float], stamp_ns: int, valid: bool, why: str = "",
              note: str = "") -> bytes:
        w, v = self._w, envelope_values
        N = w.N
        given = None
        if len(v) == w.size:
            exact, paper = float(v[N + 1]), float(v[N])
            noise = float(v[N + 2]) if w.noise_declared else -1.0      # the writer's -1 when none is declared
            given = (bool(valid), why, note, exact >= 0.0, noise >= 0.0)
            t = self._given.get(given)
            if t is not None:
                return t.bytes(stamp_ns, doubles=(exact, noise, paper), array=np.asarray(v[:N], dtype=float))
        m = w.msg(envelope_values, stamp_ns, valid, why, note)
        key = (m.exact_bound_valid, m.noise_bound_valid, m.why_invalid)
        t = self._kept.get(key, False)
        if t is False:
            if len(self._kept) >= self.KEEP:
                self._kept.clear()
                self._given.clear()
            try:
                t = Template(copy.deepcopy(m), stamp=("header", "stamp"),
                             doubles=[("exact_bound",), ("noise_bound",), ("paper_bound",)], array=("paper_envelope",))
            except ValueError:      # no envelope (N = 0): serialised per message
                t = None
            self._kept[key] = t
        if t is None:
            return bytes(zero_padding(m, serialize_message(m)))
        if given is not None:
            if len(self._given) >= self.KEEP:
                self._given.clear()
            self._given[given] = t
        return t.bytes(stamp_ns, doubles=(m.exact_bound, m.noise_bound, m.paper_bound),
                       array=np.frombuffer(m.paper_envelope, dtype=float))
