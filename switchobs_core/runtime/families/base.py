"""The protocol every gain family implements (:mod:`switchobs_core.families` lists them).

The observer (:class:`~switchobs_core.runtime.observer.SwitchedObserver`) owns the estimate, the exact
propagation between samples (:mod:`switchobs_core.numerics.propagation`), the transition ``Phi`` and the rigorous
bound (:mod:`switchobs_core.bounds.rigorous`). At every sample it asks its family for the gain and lets the family
apply it: the family chooses ``L`` or ``K``, writes the estimate, and reports the error map of
what it did to the observer's :meth:`~switchobs_core.runtime.observer.SwitchedObserver.apply_map` (for
``Phi``) and to the bound. A family keeps its own covariance if it has one.

Two shapes of family exist: *held-innovation* families (the paper's LMI gains: the sample's
innovation is held and its gain acts over the next step, e:switched_observer) and *correcting*
families (Kalman: ``x^+ = x^- + K (y - H x^-)`` at the sample). The protocol covers both.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, ClassVar, Protocol

import numpy as np

from ...exceptions import InvalidArgument, ScheduleError

__all__ = ["GainFamily", "check_bounds", "check_cycles"]


@dataclass(frozen=True)
class ScheduledCycle:
    """A promised cycle of a Kalman-family observer (the residence bookkeeping's design).

    Kalman gains have no per-channel ``kappa``, ``eta``, ``mu`` (the paper's quantities of LMI
    gains): they are None, and the paper's factors and envelopes are not applicable.
    """

    cycle: Any
    h_bounds: Any = None
    kappa: Any = None
    eta: Any = None
    mu: Any = None
    f: Any = None
    kind: str = "kalman"

    def label(self) -> str:
        return "any schedule (online Riccati)" if self.cycle is None else self.cycle.label()


def check_bounds(bounds: Any) -> tuple[float, float] | None:
    """A2's ``(h_min, h_max)`` as floats with ``0 < h_min <= h_max < inf`` (None passes)."""
    if bounds is None:
        return None
    hmin, hmax = (float(b) for b in bounds)
    if not (0 < hmin <= hmax and math.isfinite(hmax)):
        raise InvalidArgument(f"bounds must satisfy 0 < h_min <= h_max; got {bounds}")
    return (hmin, hmax)


def check_cycles(cycles: Any, mode: str, N: int) -> list:
    """The promised cycles of periodic (one) or sequence (K >= 1) mode, each with N times."""
    if cycles is None:
        raise InvalidArgument(f"cycles is required in {mode} mode")
    if not isinstance(cycles, (list, tuple)):
        cycles = [cycles]
    if len(cycles) == 0:
        raise InvalidArgument("cycles must hold at least one cycle")
    if mode == "periodic" and len(cycles) != 1:
        raise InvalidArgument(f"periodic mode takes exactly one cycle; got {len(cycles)} (use mode='sequence')")
    for c in cycles:
        h = getattr(c, "h", None)
        if h is None or len(h) != N:
            raise ScheduleError(f"cycles: {c!r} does not have {N} residence times h")
    return list(cycles)


class GainFamily(Protocol):
    """What the observer needs from a gain family.

    Attributes
    ----------
    name : str
        The registry name (:data:`~switchobs_core.families.REGISTRY`).
    paper_envelope : bool
        Whether the paper's envelopes ``z_i`` apply (its LMI gains only).
    holds : tuple of str
        The holds this family supports (``"innovation"``, ``"measurement"``).
    designs, promised : tuple
        The gain sets of the mode and the cycles promised for them (cycle bookkeeping).
    bounds : (float, float) or None
        A2's residence-time box (robust mode).
    noise : NoiseModel or None
        The noise model of the covariance it keeps (None: none kept).
    kalman : KalmanDesign or None
        The stored Kalman design in use (tables of the Kalman family), for diagnostics.
    """

    name: ClassVar[str]
    paper_envelope: ClassVar[bool]
    holds: ClassVar[tuple[str, ...]]
    designs: tuple
    promised: tuple
    bounds: tuple[float, float] | None
    noise: Any
    kalman: Any

    def reset(self, obs: Any) -> None:
        """Restart with the observer (after its own reset): covariance ``P0``, nothing held."""

    def fuses(self, obs: Any) -> bool:
        """Whether the family takes the coming sample's propagation step itself (then
        :meth:`sample` gets ``dt > 0`` and the observer has not stepped)."""

    def sample(self, obs: Any, t: float, dt: float, channel: int, y: np.ndarray, rows: tuple | None) -> None:
        """Take the sample: choose the gain, update ``obs._x`` (and, for held-innovation families,
        what is held), report the error maps."""

    def covariance(self, obs: Any) -> np.ndarray | None:
        """The real error covariance after the last sample (a copy), or None when none is kept."""

    def steps_covariance(self) -> bool:
        """Whether the observer's propagation steps carry the covariance (``E P E' + Q_d``)."""

    def held_noise(self, obs: Any, e: Any) -> np.ndarray | None:
        """The covariance the held measurement noise adds over the step ``e`` (None: none)."""

    def depart(self, obs: Any, why: str) -> None:
        """The state was set from outside (:meth:`~switchobs_core.runtime.observer.SwitchedObserver.set_estimate`):
        make the covariance the family's own (a table leaves its cache)."""

    @property
    def source(self) -> str:
        """Where the last gain came from: ``"table"`` or ``"online"`` (the Riccati recursion)."""
