"""Fixed (static) transforms from a sensor's frame to the estimator's frame.

A measurement given in another frame than the model's (a pose in ``odom`` for a model in ``map``)
is mapped into it before it is used: ``p_world = R p_frame + t`` for a point, ``q_world = q_R q``
for an orientation, ``R6 S R6'`` for a 6x6 pose covariance (x, y, z, roll, pitch, yaw; the
rotation acts on both the position and the small-angle rotation blocks). The transform is what
``static_transform_publisher --frame-id <world> --child-frame-id <frame>`` would broadcast
(tf's ``world <- frame``); it is declared, not looked up: a fixed mounting, a surveyed origin.

A transform is written as one line, ``"<frame> x y z yaw pitch roll"`` (angles in radians, Z-Y-X
as static_transform_publisher's) or ``"<frame> x y z qx qy qz qw"`` (a unit quaternion):
:func:`parse_transform`.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..exceptions import InvalidArgument

__all__ = ["FrameTransform", "parse_transform", "parse_transforms"]

_FRAME = re.compile(r"[A-Za-z_/][A-Za-z0-9_/]*")


def _quat_matrix(q: np.ndarray) -> np.ndarray:
    x, y, z, w = q
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def _ypr_quat(yaw: float, pitch: float, roll: float) -> np.ndarray:
    cy, sy = math.cos(yaw / 2), math.sin(yaw / 2)
    cp, sp = math.cos(pitch / 2), math.sin(pitch / 2)
    cr, sr = math.cos(roll / 2), math.sin(roll / 2)
    return np.array([sr * cp * cy - cr * sp * sy, cr * sp * cy + sr * cp * sy,
                     cr * cp * sy - sr * sp * cy, cr * cp * cy + sr * sp * sy])


@dataclass(frozen=True)
class FrameTransform:
    """``world <- frame``: rotation ``q`` (unit quaternion x, y, z, w; ``R`` its matrix) and
    translation ``t``."""

    frame: str
    t: np.ndarray
    q: np.ndarray

    @property
    def R(self) -> np.ndarray:
        """The 3x3 rotation matrix."""
        return _quat_matrix(self.q)

    def point(self, p: Any) -> np.ndarray:
        """``R p + t`` of a 3-vector."""
        return self.R @ np.asarray(p, dtype=float) + self.t

    def orientation(self, q: Any) -> np.ndarray:
        """``q_R q`` (Hamilton product) of an orientation quaternion (x, y, z, w)."""
        x1, y1, z1, w1 = self.q
        x2, y2, z2, w2 = np.asarray(q, dtype=float)
        return np.array([w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2, w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
                         w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2, w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2])

    def pose_covariance(self, S: Any) -> np.ndarray:
        """``R6 S R6'`` of a 6x6 pose covariance (position and rotation blocks both rotated)."""
        R6 = np.zeros((6, 6))
        R6[:3, :3] = R6[3:, 3:] = self.R
        return R6 @ np.asarray(S, dtype=float).reshape(6, 6) @ R6.T

    def describe(self) -> str:
        return (f"{self.frame} -> world: translation {np.round(self.t, 9).tolist()}, "
                f"rotation (x, y, z, w) {np.round(self.q, 9).tolist()}")


def parse_transform(text: str) -> FrameTransform:
    """A transform from ``"<frame> x y z yaw pitch roll"`` or ``"<frame> x y z qx qy qz qw"`` (a
    ``:`` after the frame is allowed); :class:`InvalidArgument` with one line saying what is wrong."""
    if not isinstance(text, str):
        raise InvalidArgument(f"{text!r} is not a string")
    parts = text.replace(":", " ", 1).split()
    form = "'<frame> x y z yaw pitch roll' or '<frame> x y z qx qy qz qw'"
    if not parts or not _FRAME.fullmatch(parts[0]):
        raise InvalidArgument(f"{text!r}: expected {form}")
    frame, nums = parts[0], parts[1:]
    try:
        v = [float(s) for s in nums]
    except ValueError:
        raise InvalidArgument(f"{text!r}: the numbers of {form} must be numbers") from None
    if len(v) not in (6, 7):
        raise InvalidArgument(f"{text!r}: {len(v)} numbers; expected {form}")
    if not all(math.isfinite(a) for a in v):
        raise InvalidArgument(f"{text!r}: every number must be finite")
    if len(v) == 6:
        q = _ypr_quat(v[3], v[4], v[5])
    else:
        q = np.array(v[3:])
        nq = float(np.linalg.norm(q))
        if abs(nq - 1.0) > 1e-6:
            raise InvalidArgument(f"{text!r}: the quaternion (qx, qy, qz, qw) has norm {nq:.9g}; give a unit one")
        q = q / nq
    return FrameTransform(frame.strip("/"), np.array(v[:3]), q)


def parse_transforms(entries: Any, world: str = "") -> dict[str, FrameTransform]:
    """``{frame: FrameTransform}`` of the entries (:func:`parse_transform`); a frame given twice, or
    the ``world`` frame itself, is an :class:`InvalidArgument`."""
    out: dict[str, FrameTransform] = {}
    for e in entries:
        tf = parse_transform(e)
        if tf.frame in out:
            raise InvalidArgument(f"frame '{tf.frame}' is given twice")
        if world and tf.frame == world.strip("/"):
            raise InvalidArgument(f"frame '{tf.frame}' is the estimator's own frame (input_frame_id): it needs no "
                                  "transform")
        out[tf.frame] = tf
    return out
