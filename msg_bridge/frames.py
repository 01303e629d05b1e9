"""Which fields of an input message are a position or an orientation, for the declared fixed
transforms of the estimator's ``input_transforms`` (:mod:`switchobs_core.model.frames`: the
numbers).

A source reads some float64 fields of its message (:class:`~msg_bridge.fields.FieldReader`). When
the message's ``header.frame_id`` has a declared transform to the estimator's frame, the
position ``(x, y, z)`` of the message (all three, whichever the source reads) is mapped by it and
the source's position fields take the mapped values; so do orientation fields (the quaternion).
Other fields (an Odometry's twist, in its child frame; a labelled array, which has no frame) are
left as they are.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from .fields import canonical_type, float64_fields

__all__ = ["FramedFields"]

#: Where the position and the orientation of each framed type are (field path prefixes).
_PATHS: dict[str, tuple[str, str | None]] = {
    "geometry_msgs/msg/PoseStamped": ("pose.position.", "pose.orientation."),
    "geometry_msgs/msg/PointStamped": ("point.", None),
    "geometry_msgs/msg/PoseWithCovarianceStamped": ("pose.pose.position.", "pose.pose.orientation."),
    "nav_msgs/msg/Odometry": ("pose.pose.position.", "pose.pose.orientation."),
}


class FramedFields:
    """The position and orientation fields among ``fields`` of a message ``type_name``;
    :meth:`apply` maps them by a :class:`~switchobs_core.model.frames.FrameTransform`."""

    def __init__(self, type_name: str, fields: Sequence[str]):
        name = canonical_type(type_name)
        pos, ori = _PATHS.get(name, (None, None))
        every = float64_fields(name) if pos is not None else ()
        self._pos: tuple[int, ...] | None = None       # indices of x, y, z in the parsed values
        self._ori: tuple[int, ...] | None = None       # indices of x, y, z, w
        self.pos_at: tuple[tuple[int, int], ...] = ()      # (field index, component 0..2)
        self.ori_at: tuple[tuple[int, int], ...] = ()      # (field index, component 0..3)
        if pos is not None:
            self._pos = tuple(every.index(pos + c) for c in "xyz")
            self.pos_at = tuple((k, "xyz".index(f[len(pos):])) for k, f in enumerate(fields)
                                if f.startswith(pos) and f[len(pos):] in ("x", "y", "z"))
        if ori is not None:
            self._ori = tuple(every.index(ori + c) for c in "xyzw")
            self.ori_at = tuple((k, "xyzw".index(f[len(ori):])) for k, f in enumerate(fields)
                                if f.startswith(ori) and f[len(ori):] in ("x", "y", "z", "w"))

    @property
    def framed(self) -> bool:
        """Whether the type has a frame whose transform can apply (a header and a position)."""
        return self._pos is not None

    def apply(self, every: Sequence[float], values: np.ndarray, tf: Any) -> np.ndarray:
        """``values`` (the source's fields of a message) with the position and orientation fields
        mapped by ``tf`` (a new array); ``every`` is the message's parsed float64 fields
        (:data:`~msg_bridge.parse.Parsed`), where the whole position and orientation are read."""
        out = np.array(values, dtype=float)
        if self.pos_at:
            p = tf.point([every[i] for i in self._pos])
            for k, c in self.pos_at:
                out[k] = p[c]
        if self.ori_at:
            q = tf.orientation([every[i] for i in self._ori])
            for k, c in self.ori_at:
                out[k] = q[c]
        return out
