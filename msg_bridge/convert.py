"""Reshaping between messages and numpy arrays.

Labelled arrays (``~/state``, ``~/envelope``, ``sim/truth``)
-------------------------------------------------------------
``std_msgs/Float64MultiArray`` has no header, so the stamp of the measurement a message
answers travels in the layout's padding:

* ``layout.data_offset = STAMP_PAD = 2`` and ``data[0:2] = (stamp.sec, stamp.nanosec)``
  (exact as float64); standard readers honour ``data_offset`` and skip them;
* ``layout.dim = [MultiArrayDimension(label=<labels>, size=n, stride=n)]`` where
  ``<labels>`` is the comma-separated list of element names, e.g.
  ``"camera.p_x,camera.p_y,camera.v_x,...,agent2.v_y"`` for the state and
  ``"z_1,z_2,paper_bound,exact_bound"`` for the envelope;
* ``data[2:2 + n]`` are the values.

Bodies
------
A state label ``"<body>.<q>"`` with ``q`` in ``p_x, p_y, v_x, v_y`` (or ``p``, ``v`` on a line)
names a body (the camera scenario's ``camera``, ``agent1``, ``agent2``, ...; a landmark with a
position only); bare ``p<k>``, ``v<k>`` name body ``body<k>``. :func:`bodies` finds every body
with a position; :func:`state_odometries` gives one ``nav_msgs/Odometry`` per body (velocity and
covariance for what the body's states hold).
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from geometry_msgs.msg import PoseStamped
from nav_msgs.msg import Odometry
from std_msgs.msg import Float64MultiArray, MultiArrayDimension, MultiArrayLayout

from .stamps import NS_PER_S, float_time_ns, ns_to_stamp
from .validate import BridgeError

__all__ = [
    "STAMP_PAD",
    "UNESTIMATED_VARIANCE",
    "covariance_labels",
    "odometry_covariances",
    "LabelledArrayWriter",
    "OdometryWriter",
    "Body",
    "LabelledArray",
    "bodies",
    "body_odometry",
    "describe_bodies",
    "unused_states",
    "envelope_labels",
    "labelled_array",
    "pose_to_xy",
    "state_odometries",
    "unpack_labelled",
    "xy_to_pose",
]

#: Number of leading padding elements of a labelled array: (stamp.sec, stamp.nanosec).
STAMP_PAD = 2

# --- poses -------------------------------------------------------------------------------

def pose_to_xy(msg: PoseStamped) -> np.ndarray:
    """The planar position ``[p_x, p_y]`` of a PoseStamped (z and orientation unused)."""
    p = msg.pose.position
    return np.array([p.x, p.y], dtype=float)


def xy_to_pose(p: Sequence[float], stamp_ns: int, frame_id: str) -> PoseStamped:
    """A PoseStamped at planar position ``p`` (z = 0, identity orientation)."""
    msg = PoseStamped()
    msg.header.stamp = ns_to_stamp(stamp_ns)
    msg.header.frame_id = frame_id
    msg.pose.position.x = float(p[0])
    msg.pose.position.y = float(p[1])
    msg.pose.orientation.w = 1.0
    return msg


# --- labelled arrays ----------------------------------------------------------------------

@dataclass(frozen=True)
class LabelledArray:
    """What :func:`unpack_labelled` returns."""

    stamp_ns: int
    labels: tuple[str, ...]
    values: np.ndarray


def labelled_array(values: Sequence[float], labels: Sequence[str], stamp_ns: int) -> Float64MultiArray:
    """A Float64MultiArray with the stamp in its padding and labelled elements.

    Raises :class:`~msg_bridge.validate.BridgeError` (a ``ValueError``) if the number of labels
    and values differ or a label contains a comma.
    """
    values = np.asarray(values, dtype=float).ravel()
    labels = tuple(labels)
    if len(labels) != values.size:
        raise BridgeError(f"{values.size} values but {len(labels)} labels")
    if any("," in lab for lab in labels):
        raise BridgeError("labels must not contain ','")
    n = values.size
    stamp_ns = int(stamp_ns)
    msg = Float64MultiArray()
    msg.layout = MultiArrayLayout(
        dim=[MultiArrayDimension(label=",".join(labels), size=n, stride=n)], data_offset=STAMP_PAD
    )
    data = np.empty(STAMP_PAD + n)
    data[0], data[1] = divmod(stamp_ns, NS_PER_S)
    data[STAMP_PAD:] = values
    msg.data = data.tolist()
    return msg


def unpack_labelled(msg: Float64MultiArray) -> LabelledArray:
    """Inverse of :func:`labelled_array`. Raises :class:`~msg_bridge.validate.BridgeError` on another
    layout or a stamp that is not a valid time (inf, NaN, negative, fractional)."""
    lay = msg.layout
    if lay.data_offset != STAMP_PAD or len(lay.dim) != 1:
        raise BridgeError(
            f"not a labelled switchobs array (data_offset {lay.data_offset}, {len(lay.dim)} dims; "
            f"expected data_offset {STAMP_PAD} and 1 dim)"
        )
    n = lay.dim[0].size
    data = np.asarray(msg.data, dtype=float)
    if data.size != STAMP_PAD + n:
        raise BridgeError(f"layout says {n} elements after the stamp but data has {data.size - STAMP_PAD}")
    labels = tuple(lay.dim[0].label.split(",")) if n else ()
    if len(labels) != n:
        raise BridgeError(f"{len(labels)} labels for {n} elements")
    return LabelledArray(labelled_stamp_ns(data[0], data[1]), labels, data[STAMP_PAD:].copy())


def labelled_stamp_ns(sec: float, nsec: float) -> int:
    """The stamp (ns) a labelled array carries as two doubles; :class:`~msg_bridge.validate.BridgeError`
    unless a valid time (:func:`msg_bridge.stamps.float_time_ns`: whole numbers with ``0 <= sec``,
    ``0 <= nsec < 1e9`` and the stamp an int64 of ns)."""
    ns = float_time_ns(sec, nsec)
    if ns is None:
        raise BridgeError(f"labelled array stamp ({float(sec)!r}, {float(nsec)!r}) is not a valid time "
                          "(whole sec in 0..2147483647, whole nanosec < 1e9)")
    return ns


def envelope_labels(N: int, noise_bound: bool = False) -> tuple[str, ...]:
    """Element names of ``~/envelope``: ``z_1..z_N``, ``paper_bound``, ``exact_bound`` and, with a
    declared measurement-noise bound, ``noise_bound``."""
    return tuple(f"z_{i}" for i in range(1, N + 1)) + ("paper_bound", "exact_bound") \
        + (("noise_bound",) if noise_bound else ())


# --- bodies and odometry --------------------------------------------------------------------

@dataclass(frozen=True)
class Body:
    """A body in the state vector: its name and the state indices of its position ``p_x``
    (always), ``p_y`` (a planar body) and velocity ``v_x``, ``v_y`` (None where the state has none:
    a landmark has no velocity, a cart on a line no ``y``)."""

    name: str
    p_x: int
    p_y: int | None = None
    v_x: int | None = None
    v_y: int | None = None

    @property
    def pose_pairs(self) -> tuple[tuple[int, int], ...]:
        """``(axis, state index)`` of the position entries the body has (axis 0: x, 1: y)."""
        return tuple((a, i) for a, i in ((0, self.p_x), (1, self.p_y)) if i is not None)

    @property
    def twist_pairs(self) -> tuple[tuple[int, int], ...]:
        """``(axis, state index)`` of the velocity entries the body has."""
        return tuple((a, i) for a, i in ((0, self.v_x), (1, self.v_y)) if i is not None)

    @property
    def indices(self) -> tuple[int, ...]:
        """Every state index of the body."""
        return tuple(i for _, i in self.pose_pairs + self.twist_pairs)


#: State label forms that name a body's position and velocity: ``<body>.<q>``, and a bare
#: ``p<k>`` / ``v<k>`` (a 1-D position and velocity, e.g. config/cart_pair.yaml's ``p1, v1``: body ``body<k>``).
_DOTTED = {"p_x": "p_x", "p_y": "p_y", "v_x": "v_x", "v_y": "v_y", "p": "p_x", "v": "v_x"}
_BARE = re.compile(r"([pv])_?(\d+)")


def _body_part(label: str) -> tuple[str, str] | None:
    """``(body name, Body field)`` a state label stands for, or None."""
    name, dot, q = label.rpartition(".")
    if dot:
        return (name, _DOTTED[q]) if q in _DOTTED and name else None
    m = _BARE.fullmatch(label)
    return (f"body{m.group(2)}", f"{m.group(1)}_x") if m else None


def bodies(state_labels: Sequence[str]) -> tuple[Body, ...]:
    """The bodies named by the state labels, in state order: ``"<body>.<q>"`` with ``q`` one of
    ``p_x, p_y, v_x, v_y`` (or ``p``, ``v`` for a body on a line), and bare ``p<k>``, ``v<k>`` (body
    ``body<k>``). A body needs a position: velocity alone makes none (:func:`unused_states` lists
    what no body takes)."""
    index: dict[str, dict[str, int]] = {}
    for k, lab in enumerate(state_labels):
        part = _body_part(lab)
        if part is not None and part[1] not in index.setdefault(part[0], {}):
            index[part[0]][part[1]] = k
    return tuple(Body(name, **idx) for name, idx in index.items() if "p_x" in idx)


def unused_states(state_labels: Sequence[str], body_list: Sequence[Body] | None = None) -> tuple[str, ...]:
    """The state labels that no body's odometry or marker shows (of ``body_list``, default :func:`bodies`)."""
    used = {i for b in (bodies(state_labels) if body_list is None else body_list) for i in b.indices}
    return tuple(lab for k, lab in enumerate(state_labels) if k not in used)


def describe_bodies(state_labels: Sequence[str]) -> str:
    """One line for the start-up log: the bodies found, the states each shows, and the states
    that go to no odometry or marker."""
    bs = bodies(state_labels)
    parts = [f"{b.name} ({', '.join(state_labels[i] for i in b.indices)})" for b in bs]
    rest = unused_states(state_labels, bs)
    return (f"outputs: {len(bs)} bod{'y' if len(bs) == 1 else 'ies'} with odometry and markers"
            + (f": {'; '.join(parts)}" if parts else " (no state label names a position: <body>.p_x, <body>.p, p<k>)")
            + (f"; states on no odometry or marker (only ~/state): {', '.join(rest)}" if rest else
               "; every state is on a body's odometry"))


#: Variance written for what the model does not estimate (z, roll, pitch, yaw and their rates):
#: large, so a consumer such as robot_localization does not fuse them (a zero says "certain").
UNESTIMATED_VARIANCE = 1e6


def covariance_labels(state_labels: Sequence[str]) -> tuple[str, ...]:
    """Element names of ``~/covariance``: ``"a|b"`` for entry (a, b) of P, row-major."""
    return tuple(f"{a}|{b}" for a in state_labels for b in state_labels)


def _fill_block(cov: np.ndarray, P: np.ndarray, pairs: tuple[tuple[int, int], ...]) -> None:
    for a, i in pairs:
        for b, j in pairs:
            cov[a, b] = P[i, j]


def odometry_covariances(P: np.ndarray | None, body: Body) -> tuple[list[float], list[float]]:
    """Row-major 6x6 pose and twist covariances of one body from the state covariance ``P``.

    Pose (x, y, z, roll, pitch, yaw): the block of P of the body's position entries; twist (vx,
    vy, vz, wx, wy, wz): that of its velocity entries. Everything the body's states do not
    estimate gets :data:`UNESTIMATED_VARIANCE` (a landmark's velocity, a line's y); with ``P``
    None (no covariance known) every variance does.
    """
    pose = np.zeros((6, 6))
    twist = np.zeros((6, 6))
    np.fill_diagonal(pose, UNESTIMATED_VARIANCE)
    np.fill_diagonal(twist, UNESTIMATED_VARIANCE)
    if P is not None:
        _fill_block(pose, P, body.pose_pairs)
        _fill_block(twist, P, body.twist_pairs)
    return pose.ravel().tolist(), twist.ravel().tolist()


def _at(x: np.ndarray, i: int | None) -> float:
    return 0.0 if i is None else float(x[i])


def body_odometry(x: np.ndarray, body: Body, stamp_ns: int, frame_id: str, child_frame_id: str,
                  P: np.ndarray | None = None) -> Odometry:
    """``nav_msgs/Odometry`` of one body: position and velocity from ``x`` (0 where the body has
    no such state), covariances from ``P``.

    The velocity is written in ``twist`` (REP 105 puts it in the child frame; with the
    identity orientation used here that equals the world frame). The orientation is not
    estimated: its variance (and every other unestimated one) is :data:`UNESTIMATED_VARIANCE`
    (:func:`odometry_covariances`).
    """
    msg = Odometry()
    msg.header.stamp = ns_to_stamp(stamp_ns)
    msg.header.frame_id = frame_id
    msg.child_frame_id = child_frame_id
    msg.pose.pose.position.x = _at(x, body.p_x)
    msg.pose.pose.position.y = _at(x, body.p_y)
    msg.pose.pose.orientation.w = 1.0
    msg.twist.twist.linear.x = _at(x, body.v_x)
    msg.twist.twist.linear.y = _at(x, body.v_y)
    msg.pose.covariance, msg.twist.covariance = odometry_covariances(P, body)
    return msg


def state_odometries(
    x: np.ndarray,
    body_list: Sequence[Body],
    stamp_ns: int,
    frame_id: str,
    child_frame_ids: Sequence[str] | None = None,
) -> list[Odometry]:
    """One Odometry per body (child frame = the body's name unless given)."""
    if child_frame_ids is None:
        child_frame_ids = [b.name for b in body_list]
    return [body_odometry(x, b, stamp_ns, frame_id, c) for b, c in zip(body_list, child_frame_ids)]


# --- writers: one message object per output, refilled for every publish --------------------
# rclpy serialises a message when publish() is called, so refilling the same object is safe,
# and it saves building the nested Odometry / layout objects again (about 70 us per Odometry
# on the reference machine, most of the node's time per measurement).

class LabelledArrayWriter:
    """``labelled_array`` with a reused message: ``w.msg(values, stamp_ns)``, the values written
    into the message's own ``data`` array through a numpy view.

    Assigning a numpy array to ``data`` makes the generated message convert it element by
    element to an ``array.array`` on every publish (9.7 us for the 146 values of
    ``~/covariance``, measured); writing into the view costs 0.3 us. The message and the values
    published are the same. The one labelled-array writer of the package (the node's outputs).
    """

    def __init__(self, labels: Sequence[str]):
        labels = tuple(labels)
        self.n = len(labels)
        self._msg = labelled_array(np.zeros(self.n), labels, 0)
        self._view = np.frombuffer(self._msg.data, dtype=float)     # the message's array.array

    def msg(self, values: np.ndarray, stamp_ns: int) -> Float64MultiArray:
        v = self._view
        v[0], v[1] = divmod(int(stamp_ns), NS_PER_S)
        v[STAMP_PAD:] = values
        return self._msg


class OdometryWriter:
    """``body_odometry`` with a reused message: ``w.msg(x, stamp_ns)``."""

    def __init__(self, body: Body, frame_id: str, child_frame_id: str):
        self.body = body
        self._msg = body_odometry(np.zeros(max(body.indices) + 1), body, 0, frame_id, child_frame_id)
        # (6x6 row-major entry, P row, P column) of the covariance blocks the body has
        self._cov = tuple((6 * a + b, i, j) for pairs in (body.pose_pairs, body.twist_pairs)
                          for a, i in pairs for b, j in pairs)
        self._n_pose = len(body.pose_pairs) ** 2

    def msg(self, x: np.ndarray, stamp_ns: int, P: np.ndarray | None = None) -> Odometry:
        m, b = self._msg, self.body
        if P is not None:
            pc, tc = m.pose.covariance, m.twist.covariance
            for k, (e, i, j) in enumerate(self._cov):
                (pc if k < self._n_pose else tc)[e] = P[i, j]
        sec, nsec = divmod(int(stamp_ns), NS_PER_S)
        m.header.stamp.sec = sec
        m.header.stamp.nanosec = nsec
        m.pose.pose.position.x = float(x[b.p_x])
        if b.p_y is not None:
            m.pose.pose.position.y = float(x[b.p_y])
        if b.v_x is not None:
            m.twist.twist.linear.x = float(x[b.v_x])
        if b.v_y is not None:
            m.twist.twist.linear.y = float(x[b.v_y])
        return m
