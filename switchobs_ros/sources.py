"""The estimator's input sources, as its pipeline reads and checks their messages.

The system's input specification (:mod:`msg_bridge.inputs`) names the sources: topic, message
type, fields -> output rows, and the channel they belong to (or shared by all). A
:class:`Source` is one of them with what the pipeline needs: the rows it feeds in each channel's
output ``y_i = C_i x`` (e:outputs), its reader, and :meth:`Source.checked`, which reads a
message and says why it is rejected (:mod:`msg_bridge.validate`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

import msg_bridge as mb
from msg_bridge import Reason, Rejection

__all__ = ["Source", "sources_from_specs"]

_POSE_TYPE = "geometry_msgs/msg/PoseStamped"


@dataclass(frozen=True)
class Source:
    """One input source as the pipeline uses it (built from a :class:`msg_bridge.InputSource`).

    ``rows[c - 1]`` are the rows of channel ``c``'s output that the source's fields feed;
    ``channel`` is None for a source shared by several channels; ``shared`` is True when its
    rows are the same quantities in every channel (the camera's own pose), so its samples need
    no channel to be read; ``read`` is the type's :class:`msg_bridge.FieldReader` ``read``;
    ``pose`` selects the PoseStamped checks of :func:`msg_bridge.check_pose`.
    """

    index: int
    topic: str
    type: str
    fields: tuple[str, ...]
    channel: int | None
    rows: tuple[tuple[int, ...], ...]
    shared: bool
    read: Any
    pose: bool

    def checked(self, msg: Any, *, frame_id: str, max_abs: float, last_ns: int | None, now_ns: int,
                future_tolerance_ns: int) -> tuple[int, np.ndarray, Rejection | None]:
        """The message's stamp and values, and why it is rejected (None: valid): values not finite
        or above ``max_abs``, another frame than ``frame_id`` (empty: any), a stamp not after
        ``last_ns`` (the source's previous one) or more than ``future_tolerance_ns`` ahead of the
        node clock ``now_ns``."""
        if self.pose:      # every field of a pose checked
            rej = mb.check_pose(msg, frame_id=frame_id, max_abs=max_abs, last_ns=last_ns, now_ns=now_ns,
                                future_tolerance_ns=future_tolerance_ns)
            if rej is not None and rej.reason is Reason.BAD_STAMP:
                return 0, np.empty(0), rej
            stamp_ns, _, values = self.read(msg)
            return stamp_ns, values, rej
        try:
            stamp_ns, frame, values = self.read(msg)
        except mb.BridgeError as err:       # a bad stamp, or a labelled array of another layout
            return 0, np.empty(0), err.rejection or Rejection(Reason.BAD_LAYOUT, "layout", str(err))
        values = np.asarray(values, dtype=float)
        rej = mb.check_values(values, self.fields, max_abs=max_abs)
        if rej is None and frame_id and self.type != mb.LABELLED_ARRAY and frame != frame_id:
            rej = Rejection(Reason.WRONG_FRAME, "header.frame_id", f"'{frame}' (expected '{frame_id}')")
        if rej is None:
            rej = mb.check_stamp(stamp_ns, last_ns=last_ns, now_ns=now_ns, future_tolerance_ns=future_tolerance_ns)
        return stamp_ns, values, rej


def sources_from_specs(specs: Any, system: Any) -> list[Source]:
    """The pipeline's sources of an input specification (:class:`msg_bridge.InputSpecs`).

    A source is *shared* when it serves every channel and feeds the same rows of ``C`` in each
    (the camera's own pose; :class:`msg_bridge.InputSource`): its samples need no channel to be read.
    """
    out = []
    for k, spec in enumerate(specs.sources):
        rows = tuple(tuple(spec.rows_for(c)) for c in range(1, system.N + 1))
        out.append(Source(k, spec.topic, spec.type, tuple(spec.fields), spec.channel, rows, bool(spec.shared),
                          spec.reader.read, spec.type == _POSE_TYPE))
    return out
