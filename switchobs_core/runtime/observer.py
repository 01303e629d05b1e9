"""The online switched Luenberger observer (Section 4, e:switched_observer).

.. math::

    \\dot{\\hat x}(t) = A \\hat x(t) + B u(t) + L(t) \\big(y(t) - C_{\\rho(t)} \\hat x(t)\\big)

driven by samples ``(t_k, rho_k, y_k)``. Between two samples the observer is propagated
exactly (augmented matrix exponentials of :mod:`switchobs_core.numerics.propagation`, cached per
(gain, step)) with what the last sample said held constant:

``hold="innovation"`` (default)
    the innovation ``nu_k = y_k - C_i x_hat(t_k)`` is held:
    ``x_hat(t_{k+1}) = e^{A dt} x_hat(t_k) + Gamma_A (B u_k + L_i nu_k)``. The error then
    obeys ``x_tilde(t_{k+1}) = (e^{A dt} - Gamma_A L_i C_i) x_tilde(t_k)`` exactly, whatever
    the plant does, so the exact bound is a guarantee for sampled outputs too, and the
    error converges on plants with unstable modes at any sample rate the design allows.
``hold="measurement"``
    the measurement ``y_k`` is held (the literal zero-order hold of e:switched_observer):
    ``x_hat(t_{k+1}) = e^{M dt} x_hat(t_k) + Gamma_M (B u_k + L_i y_k)``, ``M = A - L_i C_i``.
    The held y lags a moving plant, so the error picks up a term driven by the plant state
    (first order in 1/rate; :func:`switchobs_core.sim.simulate.sampled_error_transition`). On
    the paper's model at 100 Hz the error grows with the unstable agents (33x in 40 s),
    which is why it is not the default.

Dead time (:mod:`switchobs_core.model.schedule`). With LMI gains designed for a cycle with a dead
time ``d``, a sample less than ``d`` after its switching instant gets no gain (the design's
extra inactive interval: ``x_hat`` is propagated open loop, ``L = 0``), whatever rows it holds.
The Kalman families correct with the rows the sample holds (the shared rows while blind), with
the stored gain of that blind phase.

Both coincide with the continuous-output observer as the sample rate grows (first order in the step). A
change of channel is a switching instant (e:switching_instants). The gains of a gain family
(:mod:`switchobs_core.families`) come from a :class:`switchobs_core.table.gains.GainTable`, one design per
cycle by the mode (``periodic``, ``sequence``, ``robust``: :mod:`switchobs_core.runtime.sequence`, which also
keeps a :class:`CycleRecord` of every cycle). The observer propagates, hands each sample to its family and
applies what the family returns (the estimate, the error maps into ``Phi`` and the rigorous bound;
:mod:`switchobs_core.runtime.families.base`); it never names a family.

Channel numbers are 1-based, as in the paper and docs/api.md; paper labels (``e:...``, ``t:...``)
resolve to numbers in ``docs/equations.md``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from ..bounds.envelope import Envelope, EnvelopeTracker
from ..bounds.envelope import alpha as _alpha
from ..certificate.paper import design_dead_time
from ..families import FAMILY_NAMES, family_entry, family_of_table
from ..model.decomposition import observability_decomposition
from ..model.noise import NoiseModel
from ..model.schedule import BLIND_TOL
from ..numerics.propagation import DEFAULT_DT_RESOLUTION, ZOHCache, ZOHEntry
from ..numerics.rounding import assembled
from ..numerics.scaling import balance
from ..table.kalman import KalmanDesign
from .arguments import (
    HOLDS,
    MAX_ABS_SAMPLE,
    MODES,
    check_disturbance,
    check_hold,
    check_noise_max,
    check_options,
    check_sample,
    check_set,
    check_time,
    check_transition,
    initial_state,
    input_change,
    nonnegative,
)
from .bound_option import bound_form
from .covariance import set_entries
from .cycles import CycleRecord, Residence
from .error_bounds import ErrorBounds
from .error_maps import apply_zoh, zoh_step
from .families.base import OPEN_LOOP, Correction, FamilyContext, Sample, ScheduledCycle
from .held_input import HeldInput
from .priors import PriorCache
from .sequence import DesignSequence
from .transition import Transition

__all__ = ["FAMILIES", "HOLDS", "MAX_ABS_SAMPLE", "MODES", "NOT_APPLICABLE", "ScheduledCycle", "SwitchedObserver"]

#: Value of the paper's envelopes z_i and bound for gains they do not apply to (Kalman families).
NOT_APPLICABLE = -1.0
#: Gain families (:data:`switchobs_core.families.REGISTRY`): LMI gains, Kalman tables, online Riccati.
FAMILIES = FAMILY_NAMES

class SwitchedObserver:
    """Switched Luenberger observer with exact ZOH propagation (e:switched_observer).

    ``obs = SwitchedObserver(system, table, mode="periodic", cycles=[c])``

    Parameters
    ----------
    system : LTISystem
        Provides ``A (n, n)``, ``B (n, m)``, ``C`` (tuple of ``(p_i, n)``) and
        ``decomposition(i)`` (for alpha, e:alpha_def).
    table : GainTable
        Provides ``lookup(cycle) -> CycleDesign`` and ``robust``. A CycleDesign has
        per-channel ``L`` (n x p_i, embedded gains ``L_i = T_i [L_o; 0]``, e:L_original),
        ``kappa``, ``eta``, ``mu`` and ``cycle``.
    mode : {"periodic", "sequence", "robust"}
    cycles : sequence of Cycle, optional
        Required for periodic (one cycle) and sequence (K >= 1 cycles); ignored for robust.
    x0 : (n,) array_like, optional
        Initial estimate ``x_hat(t0)`` (zeros by default).
    t0 : float
        Initial time in seconds.
    e0 : float or None
        Initial error bound ``||x_tilde(t0)|| <= e0`` (None: unknown, no bound until :meth:`recertify`).
    bounds : (float, float), optional
        ``(h_min, h_max)`` of A2 for robust mode; default ``table.robust.h_bounds``.
    match_tol, cache_size, dt_resolution, max_records : float, int, float or None, int
        Tolerance in seconds on each measured ``h_i`` (default 0.05); LRU size of the ZOH step cache (64)
        and its step quantum (1 ns, :mod:`switchobs_core.numerics.propagation`); :class:`CycleRecord` kept.
    hold : {"innovation", "measurement"}
        What is held between samples (module docstring). Default ``"innovation"``.
    family : {"lmi", "kalman", "kalman-online"}, optional
        Gain family (default: the table's; ``"kalman-online"`` runs the Riccati recursion online
        with any table; a kalman table in robust mode does so too).
    noise : NoiseModel, optional
        Noise model of the covariance ``P`` (Kalman tables bring their own).
    track_covariance : bool, optional
        LMI gains: propagate ``P`` under ``noise`` (default: when ``noise`` is given).
    relock_rtol : float
        Kalman table: the online recursion returns to the table when its covariance is within
        this relative distance of the stored one (default 1e-3: the published covariance, the
        stored one from then on, stays within about 1 % of the real one; see
        :mod:`switchobs_core.runtime.families.kalman`).
    rounding_bound : bool
        Keep the exact bound with floating-point rounding (:mod:`switchobs_core.numerics.rounding`;
        about 9 us per sample for n = 12). Off: ``envelope().exact_bound`` is ``inf`` (no bound).
    noise_max : float or (N,) sequence of float, optional
        A declared bound on the measurement noise, ``|v_j| <= noise_max`` for every row ``j`` (one value
        for all channels, or one per channel). The observer then also keeps ``envelope().noise_bound``, a
        rigorous bound on the error of the computed estimate under any noise within that bound (the exact
        bound's argument with the noise's image added to each step, :mod:`switchobs_core.numerics.rounding`;
        about as much work again per sample). Needs ``rounding_bound`` and innovation hold.
    disturbance : Disturbance, optional
        A declared ``x' = A x + B_w w``, ``|w_j| <= max_j`` (:mod:`switchobs_core.model.disturbance`): ``noise_bound``
        holds for every such ``w`` (:mod:`switchobs_core.numerics.disturbance_reach`). Needs ``noise_max``.
    transition : bool, optional
        Keep the error transition :attr:`Phi` (an n x n product per sample): True from the
        start, False never, None (default) from its first read if that comes within a budget of
        samples after the reset (:meth:`apply_map`).
    bound : {"ellipsoid", "phase"}
        The rigorous bounds' form: ellipsoids (default), or for a Kalman table scalars in a norm fixed
        per phase on the table's periodic grid (:mod:`switchobs_core.runtime.bound_option`: cheaper, looser).

    Raises
    ------
    InvalidArgument
        On a bad mode, cycle list, x0, t0 or e0.

    Notes
    -----
    Samples before the first one are propagated open loop (``L = 0``). The design index of cycle
    ``k`` is ``k mod K`` in sequence mode; the partial cycle before the first channel-1 start uses
    design 0. The exact bound is ``||Phi(t, t0)|| e0``, ``Phi(t, t0)`` the product of the steps'
    error maps: a guarantee for the sampled observer with ``hold="innovation"`` (noise-free
    samples), only in the continuous-output limit with ``hold="measurement"``
    (:func:`switchobs_core.sim.simulate.sampled_error_transition`). The paper's bound
    ``alpha * sum z_i`` is reported as the paper's claim, not as a guarantee.
    """

    def __init__(self, system: Any, table: Any, mode: str = "periodic", cycles: Sequence[Any] | None = None,
                 x0: Any = None, t0: float = 0.0, e0: float | None = 1.0, *,
                 bounds: tuple[float, float] | None = None, match_tol: float = 0.05, cache_size: int = 64,
                 dt_resolution: float | None = DEFAULT_DT_RESOLUTION, max_records: int = 100_000,
                 hold: str = "innovation", family: str | None = None, noise: NoiseModel | None = None,
                 track_covariance: bool | None = None, relock_rtol: float = 1e-3, rounding_bound: bool = True,
                 noise_max: float | Sequence[float] | None = None, transition: bool | None = None,
                 disturbance: Any = None, bound: str = "ellipsoid"):
        self.system = system
        self.table = table
        self.A = np.ascontiguousarray(system.A, dtype=float)
        self.n = self.A.shape[0]
        B = np.asarray(system.B, dtype=float)
        self.B = B.reshape(self.n, -1) if B.size else np.zeros((self.n, 0))
        self.m = self.B.shape[1]
        self.C = tuple(np.ascontiguousarray(Ci, dtype=float) for Ci in system.C)
        self.N = len(self.C)
        self.p = tuple(Ci.shape[0] for Ci in self.C)
        self.match_tol = check_options(mode, hold, match_tol, cache_size, max_records)
        self.mode, self.hold = mode, hold
        # 1. gain family (module docstring, switchobs_core.families): the table's, or another on
        #    request; a family with no promised schedule in robust mode hands over to its entry's
        entry = family_entry(family_of_table(table) if family is None else family)
        if mode == "robust":
            entry = family_entry(entry.robust)
        Family = entry.type()
        check_hold(hold, entry.name, Family.holds)
        self.family, self.rounding_bound = entry.name, bool(rounding_bound)
        self.noise_max = check_noise_max(noise_max, self.N, self.rounding_bound, hold)
        self.disturbance = check_disturbance(disturbance, self.n, self.noise_max)
        self.relock_rtol = nonnegative("relock_rtol", relock_rtol, repr(relock_rtol))
        # 2. the family (designs of the mode, gains, covariance): it reads the observer through its
        #    context only (switchobs_core.runtime.families.base)
        ctx = FamilyContext(system, self.A, self.B, self.C, self.n, self.N, self.p, hold, dt_resolution,
                            self._register, self._zoh)
        self._gains = gains = Family(ctx, table, mode, cycles, bounds=bounds, noise=noise,
                                     track_covariance=track_covariance, relock_rtol=self.relock_rtol)
        self.designs, self.promised, self.bounds = gains.designs, gains.promised, gains.bounds
        self.kalman: KalmanDesign | None = gains.kalman
        self.noise: NoiseModel | None = gains.noise
        self.track_covariance = bool(gains.track_covariance)
        # 3. alpha of (e:alpha_def) from the observable subspaces
        try:
            self.alpha = float(system.alpha)
        except AttributeError:
            self.alpha = _alpha([observability_decomposition(self.A, Ci).T_o for Ci in self.C])
        self.e0 = None if e0 is None else nonnegative("e0", e0, float(e0))
        # balanced coordinates of A: the bound's norms and proven expm errors are taken there
        self._scale = balance(self.A, np.vstack(self.C))
        self._cache = ZOHCache(cache_size, dt_resolution, scale=self._scale)
        self._cache.register(OPEN_LOOP, self.A, None, self.B)
        self._in, self._priors = HeldInput(), PriorCache()
        self._seq = DesignSequence(self.designs, self.promised, mode, self.N, self.bounds, self.match_tol, t0,
                                   max_records)
        # the transition Phi (apply_map): measurement hold's exact bound reads it at every envelope
        check_transition(transition)
        self._phi = Transition(self.n, "kept" if transition or self.hold == "measurement" else
                               "held" if transition is None else "off")
        # the published bounds: the rounding-aware ellipsoids (innovation hold), ||Phi|| e0 (measurement)
        self._bounds = ErrorBounds(self.A, max(self.p), self.e0, self.noise_max, hold, self.rounding_bound,
                                   self._phi, B=self.B, scale=self._scale, disturbance=self.disturbance)
        self._bound = self.rounding = self._bounds.rigorous   # public: RoundingBound.clock (stamp errors)
        self.bound_form = bound_form(bound, self.family, self._gains, self._bound, self.disturbance, self._scale)
        self._x0_init, self._t0_init, self._na = x0, t0, np.full(self.N, NOT_APPLICABLE)   # _na: copied per envelope
        self.reset(x0, t0)

    # ------------------------------------------------------------------ state
    def reset(self, x0: Any = None, t0: float | None = None) -> None:
        """Restart at ``x_hat(t0) = x0`` (zeros if None; ``t0`` defaults to the constructor's): the ZOH
        cache is kept; cycle records, envelopes and ``Phi`` are cleared."""
        self._x, t0 = initial_state(x0, self._t0_init if t0 is None else t0, self.n)
        self._t = self._ts = t0          # the observer's time; the last sample's (or t0)
        self.t0 = t0
        self._blind_until = -math.inf     # LMI gains: no correction before this time (dead time)
        self._in.reset()                  # the input held, and its changes ahead
        self._phi.reset()
        self._bounds.reset()
        self._seq.reset(t0)
        self._tracker = EnvelopeTracker(self.designs[0].mu, self.e0 or 0.0, t0) if self._gains.paper_envelope else None
        self._gains.reset()     # covariance P0, nothing held: the family's own
        self._lost = ""

    gains = property(lambda self: self._gains, doc="The gain family in use (:mod:`switchobs_core.families`).")

    kalman_fallback = property(lambda self: getattr(self._gains, "fallback", ""),
                               doc="Why the Kalman table last left its cache (\"\" if it has not since the reset).")
    kalman_departures = property(lambda self: getattr(self._gains, "departures", 0),
                                 doc="Departures of the Kalman table from its cache since the reset (0 for others).")
    kalman_relocks = property(lambda self: getattr(self._gains, "relocks", 0),
                              doc="Returns of the Kalman table to its cache since the reset (0 for other families).")

    covariance_withdrawn = property(lambda self: self._lost, doc="Why :attr:`P` is None until :meth:`reset` (\"\" "
                                    "while the family's covariance holds): the recursion ran out of digits "
                                    "(:class:`~switchobs_core.runtime.families.base.Correction` ``lost``).")

    bounds_withdrawn = property(lambda self: self._bounds.withdrawn, lambda self, why: self._bounds.withdraw(why),
                                doc="Why the rigorous bounds are ``inf`` until :meth:`reset` or :meth:`recertify` "
                                "(\"\" while they hold): they could no longer be computed, or a caller that publishes "
                                "none set it (the sets then rest); the estimate is kept (module bounds.rigorous).")

    def recertify(self, e: float) -> bool:
        """Restart the rigorous bounds from ``||x - x_hat|| <= e`` now (:mod:`~switchobs_core.runtime.recertify`)."""
        return self._bounds.restart(float(e))

    @property
    def x_hat(self) -> np.ndarray:
        """Current estimate ``x_hat(t)`` (a copy), shape (n,)."""
        return self._x.copy()

    @property
    def t(self) -> float:
        """The observer's time: of the last sample, :meth:`set_estimate` or :meth:`hold_input` (or the reset)."""
        return self._t

    @property
    def channel(self) -> int:
        """Active channel, 1-based (0 before the first sample)."""
        return self._seq.cycles.channel

    @property
    def design_index(self) -> int:
        """Index into ``designs`` of the gains in use."""
        return self._seq.index

    @property
    def current_design(self) -> Any:
        """The CycleDesign whose gains are in use."""
        return self._seq.design

    @property
    def completed_cycles(self) -> list[CycleRecord]:
        """The completed cycles, oldest first (at most ``max_records``)."""
        return list(self._seq.records)

    resyncs = property(lambda self: self._seq.resyncs,
                       doc="Re-syncs of sequence mode since the reset (:mod:`switchobs_core.runtime.sequence`).")

    @property
    def Phi(self) -> np.ndarray:
        """Error transition ``Phi(t, t0)``, the product of the steps' error maps ``E``: with innovation hold exact
        for sampled outputs (``x_tilde(t) = Phi x_tilde(t0)``, no noise, a known input); else error to error."""
        return self._phi.read().copy()

    def apply_map(self, E: np.ndarray) -> None:
        """``Phi <- E Phi`` for a step with error map ``E``: formed only for a reader
        (``transition``; held until the first read of :attr:`Phi` within a budget of held maps,
        then kept at every step; :class:`~switchobs_core.runtime.transition.Transition`)."""
        self._phi.hold(E)

    cache: ZOHCache = property(lambda self: self._cache, doc="The ZOH step cache (``hits``, ``misses``).")

    # ------------------------------------------------------------------ the family's context
    def _register(self, key: Any, M: np.ndarray, L: np.ndarray | None = None, B: np.ndarray | None = None, *,
                  C: np.ndarray | None = None) -> None:
        """:attr:`FamilyContext.register`: a gain's step in the ZOH cache."""
        self._cache.register(key, M, L, B, C=C)

    def _zoh(self, key: Any, dt: float) -> ZOHEntry:
        """:attr:`FamilyContext.zoh`: the cached step of a registered key over ``dt``."""
        return self._cache.step(key, dt)

    def _held(self) -> tuple[Any, np.ndarray | None]:
        """The ZOH key and the held vector of the family's hold (the open loop and None: nothing held)."""
        h = self._gains.held
        return (OPEN_LOOP, None) if h is None else (h.key, h.v)

    # ------------------------------------------------------------------ samples
    def update(self, t: float, channel: int, y: Any, u: Any = None, rows: Any = None) -> np.ndarray:
        """Take one sample ``y = C_channel x(t)`` (or the ``rows`` of it) at time ``t``.

        Propagate exactly from the last time to ``t`` with the current gain and the last
        sample's innovation (or, with ``hold="measurement"``, the sample) held, then hold the
        new one (and ``u``) from ``t`` on. A change of channel is a switching instant.

        Parameters
        ----------
        t : float
            Sample time in seconds, ``t >= obs.t``.
        channel : int
            Active channel, 1-based.
        y : (p_channel,) or (len(rows),) array_like
            The measurement.
        u : (m,) array_like, optional
            Input held from ``t`` on (zero if None).
        rows : sequence of int, optional
            0-based positions of the rows of ``C_channel`` that ``y`` holds (partial-state
            input, e.g. only the camera rows); the matching columns of ``L_channel`` are used.

        Returns
        -------
        (n,) ndarray
            ``x_hat(t)`` (the observer's own array; copy it to keep it).

        Raises
        ------
        InvalidArgument
            ``t`` earlier than the current time or not finite, channel out of range,
            ``y``/``u``/``rows`` of the wrong size or not finite.
        """
        dt, y, u, rows = check_sample(t, self._t, channel, y, u, rows, self.p, self.m)
        # 1. exact step over [t_prev, t]: x <- Phi x + GL v_held + GB u_held, v = nu or y
        #    (a family may fuse it with its correction: the Kalman table's one map per phase)
        fuse = self._gains.fuses(self._in.u is not None or self._in.pending(t))
        if dt > 0 and not fuse:
            self._step(dt, t)
        self._bounds.changed()
        self._t = t
        self._in.settle(t)
        # 2. switching instant (the channel and the design index as their properties read them)
        if channel != (seq := self._seq).cycles.channel:
            self._switch(t, channel)
        # 3. hold the new sample's input from t on; the family takes the sample (holds its
        #    innovation, or corrects) and the observer applies what it returns (x, Phi, the bound)
        if u is not None:
            self._in.u = u if u.any() else None
        self._apply(self._gains.sample(Sample(self._x, t, dt if fuse else 0.0, t - self._ts, channel, y, rows,
                                              seq.index, t < self._blind_until, self._in.u)),
                    channel)
        self._ts = t
        return self._x

    def hold_input(self, t: float, u: Any) -> None:
        """Hold the known input ``u`` (``m`` entries; None: zero) from ``t`` on (not before the observer's
        time or an earlier call's ``t``): a command between samples, at its own stamp. The next step adds
        its exact ZOH from ``t`` (:mod:`~switchobs_core.runtime.held_input`); ``B u`` cancels in the error
        (e:system), so ``Phi`` and the bounds are those without an input (rounding aside)."""
        ch = self._in.changes
        check_time(t, ch[-1][0] if ch else self._t)
        changed, u = input_change(u, self.m, self._in.last)
        if changed:
            self._in.change(t, u)
            self._in.settle(self._t)

    def _apply(self, c: Correction, channel: int) -> None:
        """A family's correction: the held innovation's rounding, each map into the bound and ``Phi``, the estimate."""
        b = self._bound
        h = c.held
        if h is not None and b is not None:    # rounding of nu = y - C x_hat, and of the data y itself
            b.hold(h.C, c.x, h.y, channel, h.y.size, self._in.u)
        for m in c.maps:
            m.apply(self._phi, b, channel)
        self._x = c.x
        self._lost = self._lost or c.lost

    def set_estimate(self, t: float, values: dict[int, float], variances: dict[int, float] | None = None) -> None:
        """Set entries of the estimate at time ``t >= obs.t`` (robot_localization's ``set_pose``).

        The observer first propagates to ``t`` exactly as between samples (the last innovation held), then
        ``x_hat[i] = values[i]``. Where the family keeps a covariance, ``P`` keeps its other entries and gets
        row/column ``i`` zeroed with ``P[i, i] = variances[i]`` (the entry's own variance, default the previous
        ``P[i, i]``); a Kalman table then runs the recursion online from that ``P`` and re-locks as after any
        departure. The exact bound no longer holds (the set entries' error is unknown): the caller must stop
        publishing it, as after :meth:`reset`. Raises InvalidArgument for ``t`` before the observer's time or
        not finite, an index out of range, a value or a variance that is not finite (variances must be >= 0).
        """
        dt = check_set(t, self._t, values, variances, self.n)
        # a cache of the recursion (the Kalman table) leaves it: the real covariance runs online
        self._gains.depart("the state was set (set_estimate); running the Riccati recursion online")
        self._advance(t, dt)
        P = self.P
        x = self._x.copy()
        for i, v in values.items():
            x[i] = float(v)
        self._x = x
        if P is not None:
            self._gains.set_covariance(set_entries(P, set(values) | set(variances or {}), variances or {}))

    def _advance(self, t: float, dt: float) -> None:
        if dt > 0:      # propagate to t (dt ahead) as between samples
            self._step(dt, t)
            self._bounds.changed()
            self._t = float(t)
            self._in.settle(t)

    def _propagated(self, key: Any, v: np.ndarray | None, dt: float, t: float) -> tuple[Any, np.ndarray, float]:
        """The step to ``t`` (``dt`` ahead) with ``key``'s matrix and ``v`` held: its ZOH entry, the
        estimate (the input's changes added) and their rounding's residual."""
        e = self._cache.step(key, dt)
        x = zoh_step(e, self._x, v, self._in.u)
        if not self._in.changes:        # no input change ahead: nothing to add, no residual
            return e, x, 0.0
        return (e, *self._in.add(x, t, lambda d: self._cache.step(key, d), self._bound and self._bound.rho_input))

    def _step(self, dt: float, t: float) -> None:
        """Exact step over ``dt`` to ``t`` with the held innovation/measurement and input (step 1): the
        estimate, its error map into ``Phi`` and the bound, the family's covariance. The held step a
        :meth:`prior` at ``t`` computed from this state is taken as it is (:mod:`~switchobs_core.runtime.priors`)."""
        key, v = self._held()
        e, x, rho = self._prior_at(t).step or self._propagated(key, v, dt, t)
        apply_zoh(self._phi, self._bound, e, dt, self._x, x, v, self._in.u, rho)
        self._x = x
        self._gains.stepped(e, dt)

    @property
    def gains_source(self) -> str:
        """Where the gain of the last sample came from: ``"table"`` (LMI or Kalman table) or
        ``"online"`` (the Riccati recursion: kalman-online, or a departure from the table)."""
        return self._gains.source

    @property
    def P(self) -> np.ndarray | None:
        """Error covariance at the last sample (a copy), or None when not tracked.

        Kalman families: the filter's real posterior covariance (a locked table: the stored
        prior of the phase with the Joseph update, which is the real one while locked; after a
        departure the recursion's own, :mod:`switchobs_core.runtime.families.kalman`). LMI gains: the
        covariance propagated under :attr:`noise` (``track_covariance``), exact for innovation hold.
        None also once the covariance is withdrawn (:attr:`covariance_withdrawn`).
        """
        return None if self._lost else self._gains.covariance()

    def _switch(self, t: float, channel: int) -> None:
        """Bookkeeping at a switching instant (e:switching_instants): the design sequence, and for
        the paper's gains the dead time after the switch and the envelope's jump."""
        d = self._seq.switch(t, channel)
        if self._tracker is not None:
            dead = design_dead_time(d)
            self._blind_until = t + dead - BLIND_TOL if dead else -math.inf
            self._tracker.switch(t, channel, d.kappa, d.eta, d.mu, dead_time=dead)

    @property
    def residence_violations(self) -> int:
        """Residences outside their designed interval since construction (kept by :meth:`reset`)."""
        return self._seq.cycles.violations

    @property
    def residence_problem(self) -> str:
        """The statement of the residence that ended at the latest switching instant, if it
        broke its interval, else "" (compare ``residence_violations`` before and after an
        update to tell whether this update ended it)."""
        return self._seq.cycles.problem_at_switch

    def residence(self) -> Residence | None:
        """The active channel's residence at the observer's time against the gains in use
        (None before the first sample); see :class:`~switchobs_core.runtime.cycles.CycleTracker`."""
        return self._seq.cycles.residence(self._t, self.current_design)

    def predict(self, t: float, *, hold: bool = False) -> np.ndarray:
        """Prediction ``x_hat(t)`` (an (n,) array) for ``t >= obs.t`` without a sample; the state is unchanged.

        ``hold`` False (default): open loop, ``xdot = A x + B u_held`` (no correction); True: what
        :meth:`update` would propagate, with the last sample held (and the input held)."""
        dt = check_time(t, self._t)
        if dt == 0:
            return self._x.copy()
        return self._held_step(float(t), dt)[1].copy() if hold else self._propagated(OPEN_LOOP, None, dt, float(t))[1]

    def _held_step(self, t: float, dt: float) -> tuple[Any, np.ndarray, float]:
        """:meth:`_propagated` with what is held, to ``t`` (``dt > 0`` ahead): once per time and state, shared by
        :meth:`predict`, :meth:`prior`, :meth:`envelope` (:mod:`~switchobs_core.runtime.priors`; read-only)."""
        c = self._prior_at(t)
        if c.step is None:
            c.step = self._propagated(*self._held(), dt, t)
        return c.step

    def _prior_at(self, t: float) -> PriorCache:
        return self._priors.at(t, self._t, self._x, self._bounds.version, self._in.version,
                               getattr(self._gains, "missing", None))

    def prior_covariance(self, t: float, cols: np.ndarray | None = None) -> np.ndarray | None:
        """The error covariance ``P^-(t)`` that :meth:`update` at ``t`` starts from (None when no covariance is
        kept; with ``cols`` its block on those states, kept for the time: :mod:`~switchobs_core.runtime.priors`):
        the family's stored one (a locked Kalman table), else the last sample's ``P`` through the step's error
        map, ``E P E' + Q_d(dt)`` (plus the held noise ``(Gamma L) R (Gamma L)'`` for LMI gains,
        :mod:`~switchobs_core.runtime.covariance`); the state is unchanged. Read-only."""
        dt = float(t) - self._t
        c = self._prior_at(float(t)) if cols is not None and math.isfinite(dt) and dt > 0 else None
        if c is not None and (B := c.block(cols)) is not None:
            return B
        S = None if self._lost or not (math.isfinite(dt) and dt > 0) else self._gains.stored_prior(float(t), dt, cols)
        P = self.P if S is None else S
        if P is None or not (math.isfinite(dt) and dt >= 0) or S is not None:
            P = P if S is not None else None
        else:
            P = P if dt == 0 else self._gains.predict_covariance(P, self._cache.step(self._held()[0], dt), dt)
            P = P if cols is None else P[np.ix_(cols, cols)]
        return P if c is None else c.keep_block(cols, P)

    def prior(self, t: float, *, lazy: bool = False) -> tuple[np.ndarray, Any, Any]:
        """What :meth:`update` at ``t`` starts from: the prediction ``x_hat(t)`` (the last sample held) and
        the rigorous sets of its error, ``(x_hat, exact, noise)``: each the shape matrix ``S`` of an ellipsoid
        ``{S^(1/2) u : ||u|| <= 1}`` holding the error (:class:`~switchobs_core.numerics.rounding.ErrorEllipsoid`,
        rounding included; read-only, computed once per time and state: :mod:`~switchobs_core.runtime.priors`;
        ``lazy``: a :class:`~switchobs_core.numerics.rounding.PendingSet` where it is one), or a float norm bound
        where no ellipsoid is kept; ``noise`` is None without a declared ``noise_max``. The state is unchanged.
        The innovation test (:mod:`switchobs_core.runtime.consistency`) takes these."""
        if self._bound is None:
            env = self.envelope(t)
            return self.predict(t, hold=True), env.exact_bound, env.noise_bound
        dt = check_time(t, self._t)
        if dt == 0:
            return (self._x.copy(), *self._bounds.sets(None, dt, self._x, self._x, None, None))
        e, x, rho = self._held_step(float(t), dt)
        c = self._priors
        if c.sets is None:
            c.sets = self._bounds.sets(e, dt, self._x, x, self._held()[1], self._in.u, rho, lazy=True)
        return (x.copy(), *(c.sets if lazy else map(assembled, c.sets)))

    def envelope(self, t: float | None = None, *, amortised: bool | None = None) -> Envelope:
        """The paper's envelopes and bound, and the exact bound, at ``t`` (default: now).

        ``amortised`` (at the last sample's time, with the rounding-aware bound): the bounds read
        in O(n^2) between anchors (:mod:`switchobs_core.bounds.read`: rigorous, within the factor
        stated there), for a caller that publishes every sample. None (default): amortised from
        :data:`~switchobs_core.bounds.read.AMORTISED_MIN_N` states on. Never raises for a bound that
        cannot be computed: it is ``inf``, and :attr:`bounds_withdrawn` says why.

        Returns
        -------
        Envelope
            ``z`` (e:z1_evolution, e:z2_evolution), ``paper_bound = alpha sum z``
            (the paper's claim, not a guarantee; see :mod:`switchobs_core.certificate`) and
            ``exact_bound = ||Phi(t, t0)|| e0`` (ours; see the class Notes), and with a declared
            ``noise_max`` the ``noise_bound`` that holds under noise within it.
        """
        if t is None:
            t = self._t
        dt = check_time(t, self._t)
        v = self._held()[1]
        step, xp, rho = self._held_step(float(t), dt) if dt > 0 else (None, None, 0.0)
        exact, noisy = self._bounds.read(step, dt, self._x, xp, v, self._in.u, amortised, rho)
        if self._tracker is None or self.e0 is None:    # Kalman gains (the envelope is the LMI gains'), no e0
            return Envelope(z=self._na.copy(), paper_bound=NOT_APPLICABLE,
                            exact_bound=exact, t=float(t), noise_bound=noisy)
        z = self._tracker.z(float(t))
        return Envelope(z=z, paper_bound=float(self.alpha * z.sum()), exact_bound=exact, t=float(t),
                        noise_bound=noisy)
