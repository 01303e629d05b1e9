"""The typed messages of ``switchobs_msgs`` <-> numpy: the outputs ``StateEstimate`` and
``ErrorBounds``, and the stamped channel input ``ActiveChannel``.

The interface package ``switchobs_msgs`` is built from ``interfaces/switchobs_msgs`` by
``scripts/bootstrap.sh`` (``scripts/build_msgs.sh``) into the environment's prefix; this module
needs it, so :mod:`msg_bridge` does not import it: ``from msg_bridge.typed import ...``.

Writers reuse one message per output (as :class:`~msg_bridge.convert.LabelledArrayWriter`):

* :class:`StateEstimateWriter` ``.msg(x, stamp_ns, P=None)``: the labelled state and, when ``P``
  is given, its covariance row-major (empty otherwise);
* :class:`RawStateEstimateWriter`: the same as serialised bytes (:mod:`msg_bridge.raw`);
* :class:`ErrorBoundsWriter` ``.msg(envelope_values, stamp_ns, valid, why)`` from the
  ``~/envelope`` layout ``[z_1..z_N, paper_bound, exact_bound(, noise_bound)]``
  (:func:`~msg_bridge.convert.envelope_labels`), where -1 means withdrawn or not applicable.

The channel input ``ActiveChannel`` (the active channel and its switching instant, the header
stamp on the sensor's clock): :func:`active_channel` writes one, :func:`read_active_channel` gives
``(channel, switch_ns)``.

Readers (:func:`read_state_estimate`, :func:`read_error_bounds`) give numpy back, for tests and
tools. :func:`register_rosbags_types` adds both types to a ``rosbags`` type store, so the bag tools
can write them to mcap and sqlite3 bags.
"""

from __future__ import annotations

from array import array
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import switchobs_msgs
from switchobs_msgs.msg import ActiveChannel, ErrorBounds, StateEstimate

from .raw import RawMessage
from .stamps import NS_PER_S, stamp_to_ns
from .validate import BridgeError

__all__ = [
    "ACTIVE_CHANNEL",
    "active_channel",
    "read_active_channel",
    "MSG_TYPES",
    "NO_BOUND_WHY",
    "RawStateEstimateWriter",
    "BoundsReading",
    "ErrorBoundsWriter",
    "StateEstimateWriter",
    "StateReading",
    "msg_dir",
    "msg_files",
    "read_error_bounds",
    "read_state_estimate",
    "register_rosbags_types",
]

#: ROS 2 type names of the typed outputs, as the bag tools and rosbags name them.
MSG_TYPES = ("switchobs_msgs/msg/StateEstimate", "switchobs_msgs/msg/ErrorBounds")
#: The stamped channel input's type name.
ACTIVE_CHANNEL = "switchobs_msgs/msg/ActiveChannel"

#: ``why_invalid`` of a bound that is -1 while the caller gave no reason (e.g. after a reset).
NO_BOUND_WHY = "no bound known (-1): the estimate was reset or the bound is not available"


# --- writers ---------------------------------------------------------------------------------

class StateEstimateWriter:
    """``StateEstimate`` with a reused message: ``w.msg(x, stamp_ns, P=None)``.

    ``labels`` are the state labels in state order (``camera.p_x``, ...); ``x`` has one value per
    label. With ``P`` (n x n) the covariance is written row-major; without it, it is empty. The
    values go into the message's own arrays through numpy views (no per-element conversion).
    """

    def __init__(self, labels: Sequence[str], frame_id: str):
        self.labels = tuple(labels)
        self.n = len(self.labels)
        self._msg = StateEstimate()
        self._msg.header.frame_id = frame_id
        self._msg.labels = list(self.labels)
        self._msg.x = array("d", bytes(8 * self.n))
        self._x = np.frombuffer(self._msg.x, dtype=float)
        self._cov = array("d", bytes(8 * self.n * self.n))
        self._P = np.frombuffer(self._cov, dtype=float).reshape(self.n, self.n)
        self._empty = array("d")

    def msg(self, x: np.ndarray, stamp_ns: int, P: np.ndarray | None = None) -> StateEstimate:
        m = self._msg
        m.header.stamp.sec, m.header.stamp.nanosec = divmod(int(stamp_ns), NS_PER_S)
        self._x[:] = x
        if P is None:
            m.covariance = self._empty
        else:
            self._P[:] = P
            m.covariance = self._cov
        return m


class ErrorBoundsWriter:
    """``ErrorBounds`` with a reused message: ``w.msg(envelope_values, stamp_ns, valid, why)``.

    ``envelope_values`` is the ``~/envelope`` layout ``[z_1..z_N, paper_bound, exact_bound]``,
    followed by ``noise_bound`` when ``noise_declared``. The values are written as given; a bound
    is *valid* only when ``valid`` is true and the bound is >= 0 (-1 means withdrawn or not
    available). ``why_invalid`` is ``why`` (or :data:`NO_BOUND_WHY` when empty) whenever a bound
    is not valid, and ``note`` otherwise: '' for bounds from the declared ``e0``, or how and since
    when they were re-certified from data (e.g. ``re-certified from data at stamp ...``; the validity
    flags, not this text, say whether a bound holds). Raises :class:`~msg_bridge.validate.BridgeError` on a layout
    of another length.
    """

    def __init__(self, N: int, frame_id: str, noise_declared: bool):
        self.N = int(N)
        self.noise_declared = bool(noise_declared)
        self.size = self.N + 2 + self.noise_declared
        self._msg = ErrorBounds()
        self._msg.header.frame_id = frame_id
        self._msg.noise_bound_declared = self.noise_declared
        self._msg.paper_envelope = array("d", bytes(8 * self.N))
        self._z = np.frombuffer(self._msg.paper_envelope, dtype=float)
        if not self.noise_declared:
            self._msg.noise_bound = -1.0

    def msg(self, envelope_values: Sequence[float], stamp_ns: int, valid: bool, why: str = "",
            note: str = "") -> ErrorBounds:
        v = envelope_values
        if len(v) != self.size:
            raise BridgeError(f"envelope has {len(v)} values; expected {self.size} "
                              f"(z_1..z_{self.N}, paper_bound, exact_bound"
                              f"{', noise_bound' if self.noise_declared else ''})")
        m, N = self._msg, self.N
        m.header.stamp.sec, m.header.stamp.nanosec = divmod(int(stamp_ns), NS_PER_S)
        self._z[:] = v[:N]
        m.paper_bound = float(v[N])
        m.exact_bound = float(v[N + 1])
        m.exact_bound_valid = bool(valid) and m.exact_bound >= 0.0
        ok = m.exact_bound_valid
        if self.noise_declared:
            m.noise_bound = float(v[N + 2])
            m.noise_bound_valid = bool(valid) and m.noise_bound >= 0.0
            ok = ok and m.noise_bound_valid
        m.why_invalid = note if ok else (why or NO_BOUND_WHY)
        return m


class RawStateEstimateWriter:
    """:class:`StateEstimateWriter` as serialised bytes (:mod:`msg_bridge.raw`): ``w.msg(x,
    stamp_ns, P=None)``; ``w.write(...)`` the same message in the writer's own buffer, not copied
    (valid until the next write). Two layouts, one with the n x n covariance and one with it empty;
    the labels are serialised once, not at every publish."""

    def __init__(self, labels: Sequence[str], frame_id: str):
        w = StateEstimateWriter(labels, frame_id)
        n = self.n = w.n
        self._with = RawMessage(w.msg(np.zeros(n), 0, np.zeros((n, n))), stamp="header.stamp",
                                doubles={"x": ("x", n), "P": ("covariance", n * n)})
        self._without = RawMessage(w.msg(np.zeros(n), 0), stamp="header.stamp", doubles={"x": ("x", n)})

    def msg(self, x: np.ndarray, stamp_ns: int, P: np.ndarray | None = None) -> bytes:
        return bytes(self.write(x, stamp_ns, P))

    def write(self, x: np.ndarray, stamp_ns: int, P: np.ndarray | None = None) -> bytearray:
        r = self._without if P is None else self._with
        r.stamp(stamp_ns)
        r.f["x"][:] = x
        if P is not None:
            r.f["P"][:] = P.reshape(-1)
        return r.buffer


# --- readers ---------------------------------------------------------------------------------

@dataclass(frozen=True)
class StateReading:
    """What :func:`read_state_estimate` returns; ``P`` is None when no covariance was sent."""

    stamp_ns: int
    frame_id: str
    labels: tuple[str, ...]
    x: np.ndarray
    P: np.ndarray | None


@dataclass(frozen=True)
class BoundsReading:
    """What :func:`read_error_bounds` returns: the message's fields, the envelope as an array.

    :meth:`envelope` gives the ``~/envelope`` layout back.
    """

    stamp_ns: int
    frame_id: str
    exact_bound: float
    exact_bound_valid: bool
    noise_bound: float
    noise_bound_declared: bool
    noise_bound_valid: bool
    paper_bound: float
    paper_envelope: np.ndarray
    why_invalid: str

    def envelope(self) -> np.ndarray:
        """``[z_1..z_N, paper_bound, exact_bound(, noise_bound)]``, as on ``~/envelope``."""
        tail = [self.paper_bound, self.exact_bound] + ([self.noise_bound] if self.noise_bound_declared else [])
        return np.concatenate([self.paper_envelope, tail])


def read_state_estimate(msg: StateEstimate) -> StateReading:
    """Inverse of :class:`StateEstimateWriter`. Raises :class:`~msg_bridge.validate.BridgeError`
    when the labels, values and covariance sizes disagree."""
    x = np.array(msg.x, dtype=float)
    n = x.size
    if len(msg.labels) != n:
        raise BridgeError(f"StateEstimate: {len(msg.labels)} labels for {n} values")
    cov = np.array(msg.covariance, dtype=float)
    if cov.size not in (0, n * n):
        raise BridgeError(f"StateEstimate: covariance has {cov.size} values; expected 0 or {n * n} ({n} x {n})")
    return StateReading(stamp_to_ns(msg.header.stamp), msg.header.frame_id, tuple(msg.labels), x,
                        cov.reshape(n, n) if cov.size else None)


def read_error_bounds(msg: ErrorBounds) -> BoundsReading:
    """Inverse of :class:`ErrorBoundsWriter` (the message's fields, numpy for the envelope)."""
    return BoundsReading(
        stamp_to_ns(msg.header.stamp), msg.header.frame_id, float(msg.exact_bound), bool(msg.exact_bound_valid),
        float(msg.noise_bound), bool(msg.noise_bound_declared), bool(msg.noise_bound_valid),
        float(msg.paper_bound), np.array(msg.paper_envelope, dtype=float), str(msg.why_invalid),
    )


# --- the stamped channel ------------------------------------------------------------------------

def active_channel(channel: int, switch_ns: int, frame_id: str = "") -> ActiveChannel:
    """An ``ActiveChannel``: ``channel`` holds from ``switch_ns`` (the switching instant, ns on the
    sensor's clock) on."""
    m = ActiveChannel(channel=int(channel))
    m.header.stamp.sec, m.header.stamp.nanosec = divmod(int(switch_ns), NS_PER_S)
    m.header.frame_id = frame_id
    return m


def read_active_channel(msg: ActiveChannel) -> tuple[int, int]:
    """``(channel, switch_ns)`` of an ``ActiveChannel``."""
    return int(msg.channel), stamp_to_ns(msg.header.stamp)


# --- rosbags -----------------------------------------------------------------------------------

def msg_dir() -> Path:
    """The folder of the installed ``.msg`` files: ``<prefix>/share/switchobs_msgs/msg``, found
    from the imported package (``<prefix>/lib/pythonX.Y/site-packages/switchobs_msgs``)."""
    prefix = Path(switchobs_msgs.__file__).resolve().parents[4]
    d = prefix / "share" / "switchobs_msgs" / "msg"
    if not d.is_dir():
        raise BridgeError(f"switchobs_msgs has no message definitions at {d}; rebuild it (scripts/bootstrap.sh)")
    return d


def register_rosbags_types(typestore) -> None:
    """Add ``switchobs_msgs/msg/StateEstimate`` and ``.../ErrorBounds`` to a ``rosbags`` type store
    (e.g. ``get_typestore(Stores.ROS2_JAZZY)``), parsed from the installed ``.msg`` files.

    Registering again is harmless. The store must know ``std_msgs/msg/Header`` (every ROS 2
    store does).
    """
    from rosbags.typesys import get_types_from_msg

    types: dict = {}
    for name, path in msg_files():
        types.update(get_types_from_msg(path.read_text(), name))
    typestore.register(types)


def msg_files() -> list[tuple[str, Path]]:
    """``(type name, installed .msg file)`` of each switchobs_msgs type :func:`register_rosbags_types` reads."""
    d = msg_dir()
    return [(name, d / f"{name.rsplit('/', 1)[1]}.msg") for name in (*MSG_TYPES, ACTIVE_CHANNEL)]
