"""The estimator's control input: commands ``u`` on the control topic, held from their stamps on.

The system's input specification names the topic (:mod:`msg_bridge.control`: ``~/control`` by
default). A command is read into ``(stamp_ns, u)`` and checked (values finite and within
``max_abs_value``, a stamp after the previous command's and not ahead of the node clock); the
observer then holds ``u`` from that stamp on
(:meth:`~switchobs_core.runtime.observer.SwitchedObserver.hold_input`: its exact zero-order hold,
the bounds those without an input). A command must arrive before the first sample after its stamp
is answered (samples wait for the reorder window): one for a time already estimated is rejected
(``old_stamp``), never applied late. The plant did follow it, so the estimates since its stamp
were made with another input than the plant's: unless it repeats the input already held over
that time (:meth:`ControlInput.changed_the_past`), the bounds are withdrawn (re-certification
from data brings them back). Before the first sample, the commands wait here; the last one
before the first sample is the input held from it. After a reset the last command received is held
from the new first sample on.
"""

from __future__ import annotations

from collections import deque
from typing import Any

import numpy as np

import msg_bridge as mb
from msg_bridge import Reason, Rejection

__all__ = ["HISTORY", "ControlInput"]

#: Accepted commands remembered to tell whether a late one changed the input already estimated with.
HISTORY = 256


class ControlInput:
    """The commands of one control topic (:class:`msg_bridge.ControlSpec`) as the pipeline applies them."""

    def __init__(self, spec: mb.ControlSpec):
        self.spec = spec
        self.topic = spec.topic
        self._read = spec.reader.read
        self.last_ns: int | None = None        # the last accepted command's stamp
        self.latest: np.ndarray | None = None  # its u
        self.waiting: list[tuple[int | None, np.ndarray]] = []   # commands before the time origin
        self.history: deque[tuple[int, np.ndarray]] = deque(maxlen=HISTORY)   # accepted, in stamp order

    def checked(self, msg: Any, *, max_abs: float, now_ns: int, future_tolerance_ns: int,
                obs_ns: int | None) -> tuple[int, np.ndarray, Rejection | None]:
        """``(stamp_ns, u, why rejected or None)`` of a command; ``obs_ns`` the stamp of the last estimate."""
        try:
            stamp_ns, _, u = self._read(msg)
        except mb.BridgeError as err:
            return 0, np.empty(0), err.rejection or Rejection(Reason.BAD_LAYOUT, "layout", str(err))
        u = np.asarray(u, dtype=float)
        rej = mb.check_values(u, self.spec.fields, max_abs=max_abs) \
            or mb.check_stamp(stamp_ns, last_ns=self.last_ns, now_ns=now_ns, future_tolerance_ns=future_tolerance_ns)
        if rej is None and obs_ns is not None and stamp_ns < obs_ns:
            rej = Rejection(Reason.OLD_STAMP, "header.stamp",
                            f"a command for a time already estimated ({(obs_ns - stamp_ns) * 1e-9:.6f} s before the "
                            "last estimate): a command must arrive before the samples after it are answered")
        return stamp_ns, u, rej

    def changed_the_past(self, stamp_ns: int, u: np.ndarray, obs_ns: int | None) -> bool:
        """Whether a command rejected for a time already estimated (``stamp_ns`` before ``obs_ns``) gave
        the plant another input than the observer held from its stamp on: not the input held at that
        stamp repeated (the accepted commands' history; before any command the input held is 0;
        before the history's reach, or of another size: changed)."""
        if obs_ns is None or stamp_ns >= obs_ns or u.size == 0 or not np.all(np.isfinite(u)):
            return False
        held = [v for s, v in self.history if s <= stamp_ns]
        if held:
            ref = held[-1]
        elif len(self.history) < HISTORY:
            ref = np.zeros_like(u)
        else:
            return True
        return not (ref.shape == u.shape and bool(np.array_equal(ref, u)))

    def accept(self, stamp_ns: int, u: np.ndarray, observer: Any, origin_ns: int | None) -> None:
        """Hold ``u`` from ``stamp_ns`` on: in the observer once there is a time origin, else waiting for it."""
        self.last_ns, self.latest = stamp_ns, u
        self.history.append((stamp_ns, u))
        if origin_ns is None:
            self.waiting.append((stamp_ns, u))
        else:
            observer.hold_input((stamp_ns - origin_ns) * 1e-9, u)

    def start(self, observer: Any, origin_ns: int) -> None:
        """The first sample after start-up or a reset sets the time origin: the last command up to
        it is held from it, the later ones from their stamps."""
        first = [u for s, u in self.waiting if s is None or s <= origin_ns]
        if first:
            observer.hold_input(0.0, first[-1])
        for s, u in self.waiting:
            if s is not None and s > origin_ns:
                observer.hold_input((s - origin_ns) * 1e-9, u)
        self.waiting = []

    def restart(self) -> None:
        """After a reset: the last command received is held from the next time origin; stamps start over."""
        self.waiting = [] if self.latest is None else [(None, self.latest)]
        self.history.clear()
        if self.latest is not None:
            self.history.append((-(2**63), self.latest))
        self.last_ns = None
