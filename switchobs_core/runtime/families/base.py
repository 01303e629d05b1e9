"""The protocol every gain family implements (:mod:`switchobs_core.families` lists them), and the
types it exchanges with the observer.

The observer (:class:`~switchobs_core.runtime.observer.SwitchedObserver`) owns the estimate, the
exact propagation between samples (:mod:`switchobs_core.numerics.propagation`), the transition
``Phi`` (:mod:`switchobs_core.runtime.transition`) and the rigorous bound
(:mod:`switchobs_core.bounds.rigorous`). A family owns everything about its gain: the gain
itself, what it holds between samples (:class:`Held`), its covariance and its position in a
table. The two talk through three types of this module and nothing else:

:class:`FamilyContext`
    what a family may read of its observer, fixed at construction (the system's matrices, the
    hold) and two methods on the observer's ZOH cache: :meth:`FamilyContext.register` a gain's
    step, :meth:`FamilyContext.zoh` a registered step over ``dt``. A family reads no other part
    of the observer.
:class:`Sample`
    one sample as the observer hands it over: the estimate ``x`` (the observer's array, read
    only), ``t``, the step still to take (``dt > 0`` only for a family that :meth:`GainFamily.fuses`),
    the channel, rows and data, the design index, the dead-time state and the held input.
:class:`Correction`
    what the family returns: the estimate after the sample, what it holds from now on, and the
    error maps it applied (:mod:`switchobs_core.runtime.error_maps`), in order. The observer
    applies them: the estimate, each map to ``Phi`` and to the bound's ellipsoids with its
    residual, the held innovation's rounding to the bound.

Between samples the observer propagates with what the family holds (:attr:`GainFamily.held`:
``x <- e^{A dt} x + Gamma_A (B u + L_i nu)``, e:switched_observer) and tells the family
(:meth:`GainFamily.stepped`), which carries its covariance through the same step.

Two shapes of family exist: *held-innovation* families (the paper's LMI gains: the sample's
innovation is held and its gain acts over the next step, e:switched_observer) and *correcting*
families (Kalman: ``x^+ = x^- + K (y - H x^-)`` at the sample, rows ``H`` of ``C_i``,
e:outputs). The protocol covers both.

A family module imports these types from here (the top-level package re-exports the protocol
and the checks only).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Hashable
from dataclasses import dataclass
from typing import Any, ClassVar, NamedTuple, Protocol

import numpy as np

from ...exceptions import InvalidArgument, ScheduleError

__all__ = ["GainFamily", "check_bounds", "check_cycles"]

#: ZOH cache key of the open-loop step (no gain held; the observer registers it).
OPEN_LOOP: tuple = ("open",)


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


@dataclass(frozen=True)
class FamilyContext:
    """What a gain family may read of its observer (read only, fixed at construction).

    Attributes
    ----------
    system : LTISystem
        The observer's system.
    A, B : ndarray
        ``A (n, n)`` and ``B (n, m)`` as the observer propagates them (``m = 0``: no input).
    C : tuple of ndarray
        The channels' output matrices ``C_i (p_i, n)`` (e:outputs).
    n, N : int
        Numbers of states and of channels.
    p : tuple of int
        Rows ``p_i`` of each channel's output.
    hold : str
        What is held between samples (``"innovation"`` or ``"measurement"``).
    dt_resolution : float or None
        The step quantum of the observer's ZOH cache (a covariance step uses the same).
    register : callable
        ``register(key, M, L, B, C=None)``: a gain's step ``xdot = M x + L v + B u`` in the
        observer's ZOH cache under ``key`` (with ``C``: an innovation-hold key, ``M = A``;
        :meth:`~switchobs_core.numerics.propagation.ZOHCache.register`).
    zoh : callable
        ``zoh(key, dt)``: the cached exact step of a registered key (:data:`OPEN_LOOP`: the
        observer's open loop) over ``dt``, a :class:`~switchobs_core.numerics.propagation.ZOHEntry`.
    """

    system: Any
    A: np.ndarray
    B: np.ndarray
    C: tuple
    n: int
    N: int
    p: tuple
    hold: str
    dt_resolution: float | None
    register: Callable[..., None]
    zoh: Callable[[Hashable, float], Any]

    def rows_of(self, channel: int, rows: tuple | None) -> np.ndarray:
        """``H = C_channel[rows]`` (all rows for None)."""
        C = self.C[channel - 1]
        return C if rows is None else C[list(rows)]


class Sample(NamedTuple):
    """One sample as the observer hands it to its family (:meth:`GainFamily.sample`).

    Attributes
    ----------
    x : (n,) ndarray
        The estimate at ``t`` (the observer's own array: read only; a family returns a new one),
        or at the previous sample when ``dt > 0``.
    t : float
        Sample time.
    dt : float
        The propagation step still to take up to ``t`` (> 0 only for a family that fuses it,
        :meth:`GainFamily.fuses`; else the observer has taken it and ``dt = 0``).
    span : float
        Time since the previous sample (or the reset).
    channel : int
        Active channel, 1-based.
    y : ndarray
        The data (``len(rows)`` entries, or ``p_channel``).
    rows : tuple of int or None
        The rows of ``C_channel`` that ``y`` holds (None: all).
    design : int
        Index of the design in use (:attr:`~switchobs_core.runtime.observer.SwitchedObserver.design_index`).
    blind : bool
        Whether ``t`` is inside the dead time after the switch of the design in use (LMI gains).
    u : ndarray or None
        The input the observer holds from ``t`` on (None: zero).
    """

    x: np.ndarray
    t: float
    dt: float
    span: float
    channel: int
    y: np.ndarray
    rows: tuple | None
    design: int
    blind: bool
    u: np.ndarray | None


class Held(NamedTuple):
    """What a held-innovation family holds between samples (e:switched_observer).

    Attributes
    ----------
    key : hashable
        The ZOH cache key of the gain (registered with :meth:`FamilyContext.register`).
    v : ndarray
        The held vector: the innovation ``nu = y - C_i x_hat`` (innovation hold) or the sample
        ``y`` (measurement hold); the step adds ``Gamma L v``.
    C : ndarray
        The output rows of the gain (no rows while blind).
    y : ndarray
        The sample's data (its rounding, and a declared noise's, enter the bound with ``nu``).
    """

    key: Hashable
    v: np.ndarray
    C: np.ndarray
    y: np.ndarray


class Correction(NamedTuple):
    """What a family returns for one sample (:meth:`GainFamily.sample`; a named tuple as :class:`Sample`: built
    once per sample, at half a frozen dataclass's cost).

    Attributes
    ----------
    x : (n,) ndarray
        The estimate after the sample (the sample's own ``x`` when the family does not change it).
    maps : tuple
        The error maps applied at this sample, in order (:mod:`switchobs_core.runtime.error_maps`):
        each enters ``Phi`` and, with its residual, the rigorous bound.
    held : Held or None
        What the family holds from this sample on (None: nothing newly held).
    lost : str
        Why the family's covariance no longer holds ("" while it does): its recursion ran out of
        digits at this sample and restarted (:mod:`switchobs_core.runtime.families.online`). The
        estimate and the maps are still exact for the gain applied, so the rigorous bound goes
        on; the covariance, and what rests on it (the published ``P``, the chi-square gate), is
        withdrawn until the observer's reset.
    """

    x: np.ndarray
    maps: tuple = ()
    held: Held | None = None
    lost: str = ""


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
    """What the observer needs from a gain family (module docstring).

    ``Family(ctx, table, mode, cycles, *, bounds=None, noise=None, track_covariance=None,
    relock_rtol=1e-3)`` with ``ctx`` the observer's :class:`FamilyContext`; a family keeps the
    context and reads the observer through it only.

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
    track_covariance : bool
        Whether it keeps a covariance.
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
    track_covariance: bool
    kalman: Any

    @property
    def source(self) -> str:
        """Where the last gain came from: ``"table"`` or ``"online"`` (the Riccati recursion)."""

    @property
    def held(self) -> Held | None:
        """What the observer's next propagation step holds (None: nothing, the open loop
        :data:`OPEN_LOOP`, ``x <- e^{A dt} x + Gamma_A B u``)."""

    def reset(self) -> None:
        """Restart with the observer (after its own reset): covariance ``P0``, nothing held."""

    def fuses(self, input_held: bool) -> bool:
        """Whether the family takes the coming sample's propagation step itself (then
        :meth:`sample` gets ``dt > 0`` and the observer has not stepped); ``input_held``: whether
        a nonzero input is held over that step."""

    def sample(self, s: Sample) -> Correction:
        """Take the sample: choose the gain, correct the estimate or hold the innovation, and
        return the :class:`Correction` (the estimate, what is held, the error maps applied)."""

    def stepped(self, e: Any, dt: float) -> None:
        """The observer propagated over the step ``e`` (a ZOH cache entry) of ``dt`` with what
        :attr:`held` holds: carry the covariance kept through it (``E P E' + Q_d``, plus the
        held noise)."""

    def covariance(self) -> np.ndarray | None:
        """The real error covariance after the last sample (a copy), or None when none is kept."""

    def stored_prior(self, t: float, dt: float, cols: np.ndarray | None = None) -> np.ndarray | None:
        """The prior covariance at ``t`` (``dt`` after the last sample) when the family has it stored
        (a read-only array the caller must not keep; a locked Kalman table: the next phase's; with
        ``cols``, its block on those rows and columns) or, with ``cols``, can give that block
        without the n x n prior (the online Kalman recursion: from its factor; the LMI gains: from
        a block the held step maps into itself; equal up to rounding), else None: the observer then
        propagates :meth:`covariance` (:meth:`predict_covariance`)."""

    def predict_covariance(self, P: np.ndarray, e: Any, dt: float) -> np.ndarray:
        """``P`` (as :meth:`covariance` returned it) through the step ``e`` over ``dt``, not kept
        (:meth:`~switchobs_core.runtime.observer.SwitchedObserver.prior_covariance`)."""

    def depart(self, why: str) -> None:
        """The state is about to be set from outside
        (:meth:`~switchobs_core.runtime.observer.SwitchedObserver.set_estimate`): make the
        covariance the family's own (a table leaves its cache)."""

    def set_covariance(self, P: np.ndarray) -> None:
        """Keep ``P`` as the covariance from now on (after :meth:`depart`)."""
