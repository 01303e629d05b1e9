"""``~/set_state``: a message that sets entries of the estimate (robot_localization's ``set_pose``).

The message is a labelled array in the layout of ``~/state`` (:func:`msg_bridge.labelled_array`)
naming some state entries (``agent1.p_x``) and optionally their variances (``var:agent1.p_x``),
stamped with the time they hold at. :func:`read_set_state` checks it against the state's labels;
the pipeline applies it (:meth:`~switchobs_ros.pipeline.EstimatorPipeline.on_set_state`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

import msg_bridge as mb
from msg_bridge import Reason, Rejection

__all__ = ["SET_STATE_TOPIC", "SetState", "apply_set_state", "read_set_state"]

#: The set-state input's name in the counters.
SET_STATE_TOPIC = "~/set_state"


@dataclass(frozen=True)
class SetState:
    """A checked ``~/set_state`` message: its stamp, its labels, and the values and variances it
    sets by state index (0-based)."""

    stamp_ns: int
    labels: tuple[str, ...]
    values: dict[int, float]
    variances: dict[int, float]


def read_set_state(msg: Any, state_labels: Sequence[str], max_abs: float) -> SetState | Rejection:
    """The entries ``msg`` sets, or why it is rejected: another layout, a label that names no state
    entry, a value that is not finite or above ``max_abs``, a negative variance, no entry at all."""
    try:
        arr = mb.unpack_labelled(msg)
    except mb.BridgeError as err:
        return Rejection(Reason.BAD_LAYOUT, "layout", str(err))
    index = {lab: i for i, lab in enumerate(state_labels)}
    values: dict[int, float] = {}
    variances: dict[int, float] = {}
    for lab, v in zip(arr.labels, arr.values):
        var = lab.startswith("var:")
        name = lab[4:] if var else lab
        if name not in index:
            return Rejection(Reason.BAD_LAYOUT, lab, "not a state entry (the labels of ~/state, or var:<label>): "
                             f"{', '.join(index)}")
        if not np.isfinite(v):
            return Rejection(Reason.NON_FINITE, lab, f"{v}")
        if abs(v) > max_abs or (var and v < 0):
            return Rejection(Reason.TOO_LARGE, lab, f"{v} (|v| <= {max_abs:g}, variances >= 0)")
        (variances if var else values)[index[name]] = float(v)
    if not values and not variances:
        return Rejection(Reason.BAD_LAYOUT, "labels", "names no state entry")
    return SetState(arr.stamp_ns, tuple(arr.labels), values, variances)


def apply_set_state(pipe: Any, msg: Any, now_ns: int) -> bool:
    """A ``~/set_state`` message received by the pipeline ``pipe`` at node-clock
    ``now_ns``. The observer propagates to its stamp and takes the values
    (:meth:`SwitchedObserver.set_estimate`); before the first sample they replace entries of
    the initial estimate. The exact bound is withdrawn (:data:`NO_BOUND`: the set entries'
    error is unknown) until re-certified from data. A bad message is rejected and counted; True when
    applied."""
    topic = SET_STATE_TOPIC
    try:
        st = read_set_state(msg, pipe.system.state_labels, pipe.max_abs)
        if not isinstance(st, Rejection) and st.stamp_ns - now_ns > pipe.future_ns:
            st = Rejection(Reason.FUTURE_STAMP, "stamp", f"{(st.stamp_ns - now_ns) * 1e-9:.3g} s ahead of the "
                           "node clock")
        if not isinstance(st, Rejection) and pipe.origin_ns is not None and pipe.obs_ns is not None \
                and st.stamp_ns < pipe.obs_ns:
            st = Rejection(Reason.OLD_STAMP, "stamp", "before the last estimate (the past cannot be set)")
        if isinstance(st, Rejection):
            pipe.reject(topic, st)
            return False
        if pipe.origin_ns is None:          # before the first sample: the initial estimate
            for i, v in st.values.items():
                pipe.x0[i] = v
            pipe.observer.reset(pipe.x0, 0.0)
        else:
            pipe.observer.set_estimate((st.stamp_ns - pipe.origin_ns) * 1e-9, st.values, st.variances)
            pipe.obs_ns = st.stamp_ns
        pipe.accepted[topic] += 1
        pipe.states_set += 1
        pipe.bound_valid = False
        pipe.bound_invalid_why = "state set by ~/set_state"
        pipe.log.info(f"state set at stamp {st.stamp_ns} ({', '.join(st.labels)}); exact_bound is "
                      f"{-1:g} (no bound known) from now on")
        return True
    except Exception as err:
        pipe.internal_error(topic, err)
        return False
