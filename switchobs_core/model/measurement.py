"""A measurement: all the observer and the estimator's pipeline see of a sensor.

``Measurement(stamp_ns, channel, rows, y)``: at the time ``stamp_ns`` (integer nanoseconds of the
sensor's clock) channel ``channel`` (1-based, e:system) measured

.. math::

    y = C_{\\rho}[r] \\, x(t) + v

the rows ``r`` of its output (``rows`` None: all ``p_rho`` of them, in order). Which topic,
message type and field each row came from is the input specification's business
(:mod:`msg_bridge.inputs`); the numerics never see a message.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Measurement"]


@dataclass(frozen=True)
class Measurement:
    """One sample of one channel: ``stamp_ns``, ``channel`` (1-based), ``rows`` (0-based rows of
    ``C_channel`` that ``y`` holds, in that order; None: every row) and ``y``."""

    stamp_ns: int
    channel: int
    rows: tuple[int, ...] | None
    y: np.ndarray

    @property
    def partial(self) -> bool:
        """True when the sample holds only some rows of its channel's output."""
        return self.rows is not None
