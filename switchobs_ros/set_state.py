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

__all__ = ["SET_STATE_TOPIC", "SetState", "read_set_state"]

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
