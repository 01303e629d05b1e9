"""The estimator's input sources, as its pipeline reads and checks their messages.

The system's input specification (:mod:`msg_bridge.inputs`) names the sources: topic, message
type, fields -> output rows, and the channel they belong to (or shared by all). A
:class:`Source` is one of them with what the pipeline needs: the rows it feeds in each channel's
output ``y_i = C_i x`` (e:outputs), its reader, and :meth:`Source.checked`, which reads a
message and says why it is rejected (:mod:`msg_bridge.validate`).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

import msg_bridge as mb
from msg_bridge import Reason, Rejection
from msg_bridge.frames import FramedFields
from msg_bridge.stamps import NS_PER_S, time_ns

__all__ = ["Source", "sources_from_specs"]

_POSE_TYPE = "geometry_msgs/msg/PoseStamped"


@dataclass(frozen=True)
class Source:
    """One input source as the pipeline uses it (built from a :class:`msg_bridge.InputSource`).

    ``rows[c - 1]`` are the rows of channel ``c``'s output that the source's fields feed;
    ``channel`` is None for a source shared by several channels; ``shared`` is True when its
    rows are the same quantities in every channel (the camera's own pose), so its samples need
    no channel to be read; ``read`` is the type's :class:`msg_bridge.FieldReader` ``read``;
    ``pose`` selects the PoseStamped checks of :func:`msg_bridge.check_pose`; ``parser`` reads
    a stamped type's message, bytes or parsed form into one form (:mod:`msg_bridge.parse`; None for
    the labelled array, which has no header).
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
    framed: FramedFields | None = None

    parser: mb.Parser | None = None

    def checked(self, msg: Any, *, frame_id: str, max_abs: float, last_ns: int | None, now_ns: int,
                future_tolerance_ns: int, transforms: Mapping[str, Any] | None = None
                ) -> tuple[int, np.ndarray, Rejection | None]:
        """The message's stamp and values, and why it is rejected (None: valid): bytes that are not
        a message of the type (``bad_layout``), values not finite or above ``max_abs``, another frame
        than ``frame_id`` (empty: any) with no declared transform in ``transforms`` (``{frame:
        FrameTransform}``: the positions and orientations are mapped into ``frame_id`` first,
        :mod:`msg_bridge.frames`), a stamp not after ``last_ns`` (the source's previous one) or more
        than ``future_tolerance_ns`` ahead of the node clock ``now_ns``.

        ``msg`` is the message, its serialised bytes (a subscription with ``raw=True``) or its
        :data:`msg_bridge.parse.Parsed` form: all three are checked in that form, by the same code.
        """
        if self.parser is None:
            return self._checked_labelled(msg, max_abs=max_abs, last_ns=last_ns, now_ns=now_ns,
                                          future_tolerance_ns=future_tolerance_ns)
        p = self.parser.parse(msg)
        if p.__class__ is not tuple:        # bytes that are not a message of the type
            return 0, _EMPTY, p
        sec, nsec, frame, every = p
        tf = None
        if transforms and self.framed is not None and self.framed.framed and frame != frame_id:
            tf = transforms.get(frame.strip("/"))
        if self.pose:      # every field of a pose checked
            rej = mb.check_pose(p, frame_id=None if tf else frame_id, max_abs=max_abs, last_ns=last_ns,
                                now_ns=now_ns, future_tolerance_ns=future_tolerance_ns)
            if rej is not None and rej.reason is Reason.BAD_STAMP:
                return 0, _EMPTY, rej
            values = self.parser.values(every)
            if tf is not None and rej is None:
                values = self.framed.apply(every, values, tf)
                rej = mb.check_values(values, self.fields, max_abs=max_abs)
            return sec * NS_PER_S + nsec, values, rej if rej is None else _named(rej)   # as sent: a valid time
        stamp_ns = time_ns(sec, nsec)
        if stamp_ns is None:
            return 0, _EMPTY, mb.check_time(sec, nsec)
        values = self.parser.values(every)
        rej = mb.check_values(values, self.fields, max_abs=max_abs)
        if rej is None and tf is not None:
            values = self.framed.apply(every, values, tf)
            rej = mb.check_values(values, self.fields, max_abs=max_abs)
        elif rej is None and frame_id and frame != frame_id:
            rej = _named(Rejection(Reason.WRONG_FRAME, "header.frame_id", f"'{frame}' (expected '{frame_id}')"))
        if rej is None:
            rej = mb.check_stamp(stamp_ns, last_ns=last_ns, now_ns=now_ns, future_tolerance_ns=future_tolerance_ns)
        return stamp_ns, values, rej

    def _checked_labelled(self, msg: Any, *, max_abs: float, last_ns: int | None, now_ns: int,
                          future_tolerance_ns: int) -> tuple[int, np.ndarray, Rejection | None]:
        """:meth:`checked` of a labelled array (no header, no frame: its stamp in the padding)."""
        try:
            stamp_ns, _, values = self.read(msg)
        except mb.BridgeError as err:       # a bad stamp, or a labelled array of another layout
            return 0, _EMPTY, err.rejection or Rejection(Reason.BAD_LAYOUT, "layout", str(err))
        rej = mb.check_values(values, self.fields, max_abs=max_abs)
        if rej is None:
            rej = mb.check_stamp(stamp_ns, last_ns=last_ns, now_ns=now_ns, future_tolerance_ns=future_tolerance_ns)
        return stamp_ns, values, rej

    @property
    def raw(self) -> bool:
        """Whether the source's messages can be taken as serialised bytes (a fixed layout:
        :data:`msg_bridge.parse.RAW_TYPES`)."""
        return self.parser is not None and self.parser.raw is not None


_EMPTY = np.empty(0)
_EMPTY.flags.writeable = False


def _named(rej: Rejection | None) -> Rejection | None:
    """A ``wrong_frame`` rejection naming the parameters that fix it."""
    if rej is None or rej.reason is not Reason.WRONG_FRAME:
        return rej
    return Rejection(rej.reason, rej.field, f"{rej.detail}: declare the frame's fixed transform in parameter "
                     "input_transforms ('<frame> x y z yaw pitch roll'), or publish in input_frame_id")


def sources_from_specs(specs: Any, system: Any) -> list[Source]:
    """The pipeline's sources of an input specification (:class:`msg_bridge.InputSpecs`).

    A source is *shared* when it serves every channel and feeds the same rows of ``C`` in each
    (the camera's own pose; :class:`msg_bridge.InputSource`): its samples need no channel to be read.
    """
    out = []
    for k, spec in enumerate(specs.sources):
        rows = tuple(tuple(spec.rows_for(c)) for c in range(1, system.N + 1))
        out.append(Source(k, spec.topic, spec.type, tuple(spec.fields), spec.channel, rows, bool(spec.shared),
                          spec.reader.read, spec.type == _POSE_TYPE, FramedFields(spec.type, spec.fields),
                          None if spec.type == mb.LABELLED_ARRAY else mb.Parser(spec.type, tuple(spec.fields))))
    return out
