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

Both coincide with the continuous-output observer as the sample rate grows (first order
in the step). A change of channel is a switching instant (e:switching_instants);
two consecutive starts of channel 1 bound a switching cycle (e:tau_k, e:s_k), written for N
channels visited in the cyclic order 1, 2, ..., N.

Gains come from a :class:`switchobs_core.table.gains.GainTable`. Modes:

``periodic``
    ``cycles=[c]``: one design for every cycle (the paper's periodic case).
``sequence``
    ``cycles=[c_0, c_1, ...]``: cycle k uses the design of ``c_{k mod K}`` (the paper's
    nonperiodic case, Table ``T:eta_values``).
``robust``
    the table's residence-time-box design ``table.robust``, meant for any schedule
    with ``h_min <= h_i <= h_max`` (assumption A2).

At the end of every cycle a :class:`CycleRecord` stores the measured ``tau_k``, ``h_k``,
``s_k``, the paper's factors ``f_ii = kappa_i exp(mu_i (tau - h_i) - eta_i h_i)``
(e:f11_le_delta_main) for the *measured* durations and the gains used, and whether the
cycle matched the promise (order 1..N, durations within ``match_tol`` of the scheduled
cycle; in robust mode, A2's box).

Channel numbers are 1-based, as in the paper and docs/api.md.

Paper labels (``e:...``, ``t:...``) resolve to numbers in ``docs/equations.md``.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Sequence
from typing import Any

import numpy as np

from ..bounds.envelope import Envelope, EnvelopeTracker
from ..bounds.envelope import alpha as _alpha
from ..bounds.kalman_map import sparse_transition
from ..bounds.read import AMORTISED_MIN_N
from ..bounds.rigorous import RoundingBound
from ..certificate.paper import design_dead_time
from ..design.riccati import DiscretizationCache
from ..exceptions import InvalidArgument
from ..families import FAMILY_NAMES, family_entry, family_of_table
from ..model.decomposition import observability_decomposition
from ..model.noise import NoiseModel
from ..model.schedule import BLIND_TOL
from ..numerics.kalman_step import symmetrize
from ..numerics.propagation import DEFAULT_DT_RESOLUTION, ZOHCache
from ..table.kalman import KalmanDesign
from .cycles import CycleRecord, CycleTracker, Residence
from .families.base import ScheduledCycle

__all__ = ["FAMILIES", "HOLDS", "MAX_ABS_SAMPLE", "MODES", "NOT_APPLICABLE", "ScheduledCycle", "SwitchedObserver"]

#: Value of the paper's envelopes z_i and bound for gains they do not apply to (Kalman families).
NOT_APPLICABLE = -1.0

#: Schedule modes accepted by :class:`SwitchedObserver`.
MODES = ("periodic", "sequence", "robust")
#: Gain families (:data:`switchobs_core.families.REGISTRY`): the paper's LMI gains, offline Kalman
#: tables, online Riccati.
FAMILIES = FAMILY_NAMES
#: What may be held between samples (module docstring).
HOLDS = ("innovation", "measurement")
#: Largest accepted norm of a sample (and magnitude of an input entry): beyond it the products
#: with the gains and ZOH matrices in the next step could overflow to inf (1e300 * ||Gamma L|| does).
MAX_ABS_SAMPLE = 1e150
_MAX_SQ = MAX_ABS_SAMPLE**2  # 1e300: still a finite double
#: Floating-point work (flops, about ``2 n^3`` per held map) a first read of ``Phi`` may cost: beyond
#: it (or beyond :data:`_PENDING_BYTES` of held arrays) an unread ``Phi`` is no longer kept.
_PENDING_FLOPS = 2**31
#: Bytes of distinct arrays the held maps may keep alive.
_PENDING_BYTES = 64 << 20

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
    e0 : float
        Initial error bound ``||x_tilde(t0)|| <= e0``, used by :meth:`envelope`.
    bounds : (float, float), optional
        ``(h_min, h_max)`` of A2 for robust mode; default ``table.robust.h_bounds``.
    match_tol : float
        Tolerance in seconds on each measured ``h_i`` (default 0.05).
    cache_size : int
        LRU size of the ZOH step cache (default 64).
    dt_resolution : float or None
        Step quantum of the cache (default 1 ns, see :mod:`switchobs_core.numerics.propagation`).
    max_records : int
        Number of :class:`CycleRecord` kept (oldest dropped first).
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
        A declared bound on the measurement noise, ``|v_j| <= noise_max`` for every row ``j``
        (one value for all channels, or one per channel). The observer then also keeps
        ``envelope().noise_bound``, a rigorous bound on the error of the computed estimate
        under any noise within that bound (same argument as the exact bound with the noise's
        image ``||G v|| <= ||G||_F sqrt(p) v_max`` added to each step's residual, see
        :mod:`switchobs_core.numerics.rounding`; about as much work again per sample). Needs
        ``rounding_bound`` and innovation hold.
    transition : bool, optional
        Keep the error transition :attr:`Phi` (an n x n product per sample): True from the
        start, False never, None (default) from its first read if that comes within a budget of
        samples after the reset (:meth:`apply_map`).

    Raises
    ------
    InvalidArgument
        On a bad mode, cycle list, x0, t0 or e0.

    Notes
    -----
    Samples before the first one are propagated open loop (``L = 0``). The design index
    of cycle ``k`` is ``k mod K`` in sequence mode; the partial cycle before the first
    channel-1 start uses design 0. The exact bound is ``||Phi(t, t0)|| e0`` with
    ``Phi(t, t0)`` the product of the steps' error maps. With ``hold="innovation"`` it is a
    guarantee for the sampled observer (noise-free samples): ``||x_tilde(t)|| <= ||Phi|| e0``.
    With ``hold="measurement"`` it is the error-to-error part of the joint transition (see
    :func:`switchobs_core.sim.simulate.sampled_error_transition`), a guarantee only in the
    continuous-output limit. The paper's bound ``alpha * sum z_i`` is reported as the
    paper's claim, not as a guarantee.

    Examples
    --------
    >>> obs = SwitchedObserver(sys, table, mode="periodic", cycles=[Cycle.from_ts(2.0, 0.6)])
    >>> obs.update(0.01, 1, y)          # doctest: +SKIP
    """

    def __init__(self, system: Any, table: Any, mode: str = "periodic",
                 cycles: Sequence[Any] | None = None, x0: Any = None, t0: float = 0.0,
                 e0: float = 1.0, *, bounds: tuple[float, float] | None = None,
                 match_tol: float = 0.05, cache_size: int = 64,
                 dt_resolution: float | None = DEFAULT_DT_RESOLUTION,
                 max_records: int = 100_000, hold: str = "innovation",
                 family: str | None = None, noise: NoiseModel | None = None,
                 track_covariance: bool | None = None, relock_rtol: float = 1e-3,
                 rounding_bound: bool = True, noise_max: float | Sequence[float] | None = None,
                 transition: bool | None = None):
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
        if mode not in MODES:
            raise InvalidArgument(f"mode must be one of {MODES}; got {mode!r}")
        self.mode = mode
        if hold not in HOLDS:
            raise InvalidArgument(f"hold must be one of {HOLDS}; got {hold!r}")
        self.hold = hold
        self.match_tol = float(match_tol)
        if not (math.isfinite(self.match_tol) and self.match_tol >= 0):
            raise InvalidArgument(f"match_tol must be a finite number >= 0; got {match_tol}")
        for name, v in (("cache_size", cache_size), ("max_records", max_records)):
            if not isinstance(v, (int, np.integer)) or v < 1:
                raise InvalidArgument(f"{name} must be an integer >= 1; got {v!r}")
        # 1. gain family (module docstring, switchobs_core.families): the table's, or another on
        #    request; a family with no promised schedule in robust mode hands over to its entry's
        entry = family_entry(family_of_table(table) if family is None else family)
        if mode == "robust":
            entry = family_entry(entry.robust)
        Family = entry.type()
        if hold not in Family.holds:
            raise InvalidArgument(f"hold={hold!r} is not available with the {entry.name!r} family "
                                  f"(it holds {', '.join(Family.holds)}); hold='measurement' applies to the LMI "
                                  "family only")
        self.family = entry.name
        self.rounding_bound = bool(rounding_bound)
        self.noise_max = self._check_noise_max(noise_max, hold)
        self.relock_rtol = float(relock_rtol)
        if not (math.isfinite(self.relock_rtol) and self.relock_rtol >= 0):
            raise InvalidArgument(f"relock_rtol must be a finite number >= 0; got {relock_rtol!r}")
        self._nA = float(np.linalg.norm(self.A, 2))
        # 2. the family: designs of the mode, gains, covariance
        self._gains = gains = Family(self, table, mode, cycles, bounds=bounds, noise=noise,
                                     track_covariance=track_covariance, relock_rtol=self.relock_rtol)
        self.designs, self.promised, self.bounds = gains.designs, gains.promised, gains.bounds
        self.kalman: KalmanDesign | None = gains.kalman
        self.noise: NoiseModel | None = gains.noise
        self.track_covariance = bool(gains.track_covariance)
        if self.noise is not None:
            self.noise.check_system(system)
            self._dcache = DiscretizationCache(self.A, self.B, self.noise.Q_c,
                                               dt_resolution=dt_resolution or DEFAULT_DT_RESOLUTION)
        # 2. alpha of (e:alpha_def) from the observable subspaces
        try:
            self.alpha = float(system.alpha)
        except AttributeError:
            self.alpha = _alpha([observability_decomposition(self.A, Ci).T_o for Ci in self.C])
        e0 = float(e0)
        if not (math.isfinite(e0) and e0 >= 0):
            raise InvalidArgument(f"e0 must be a finite number >= 0; got {e0}")
        self.e0 = e0
        self._cache = ZOHCache(cache_size, dt_resolution)
        self._cache.register(("open",), self.A, None, self.B)
        self._I = np.eye(self.n)
        # the rounding-aware bounds (switchobs_core.bounds.rigorous): innovation hold and Kalman
        self._bound = (RoundingBound(self.A, max(self.p), self.e0, self.noise_max)
                       if self.hold == "innovation" and self.rounding_bound else None)
        self._Crows: dict = {}
        self._records: deque = deque(maxlen=int(max_records))
        self._cycles = CycleTracker(self.N, self.mode, self.bounds, self.match_tol, float(t0))
        # the transition Phi (apply_map): measurement hold's exact bound reads it at every envelope
        if transition is not None and not isinstance(transition, (bool, np.bool_)):
            raise InvalidArgument(f"transition must be True, False or None; got {transition!r}")
        self._phi_init = ("kept" if transition or self.hold == "measurement" else
                          "held" if transition is None else "off")
        self._pending_max = int(min(max(_PENDING_FLOPS // (2 * self.n ** 3), 256), 65536))
        self._x0_init = x0
        self._t0_init = t0
        self.reset(x0, t0)

    # ------------------------------------------------------------------ state
    def reset(self, x0: Any = None, t0: float | None = None) -> None:
        """Restart at ``x_hat(t0) = x0`` (zeros if None; ``t0`` defaults to the constructor's).

        The ZOH cache is kept; cycle records, envelopes and ``Phi`` are cleared.
        """
        if t0 is None:
            t0 = self._t0_init
        t0 = float(t0)
        if not math.isfinite(t0):
            raise InvalidArgument(f"t0 must be finite; got {t0}")
        if x0 is None:
            x = np.zeros(self.n)
        else:
            x = np.array(x0, dtype=float).reshape(-1)
            if x.size != self.n:
                raise InvalidArgument(f"x0 must have n = {self.n} entries; got {x.size}")
            if not np.isfinite(x).all():
                raise InvalidArgument("x0 has a non-finite entry")
        self._x = x
        self._t = t0
        self.t0 = t0
        self._channel = 0
        self._blind_until = -math.inf     # LMI gains: no correction before this time (dead time)
        self._y = np.zeros(0)
        self._u = np.zeros(self.m)
        self._u_zero = True
        self._key = ("open",)
        self._entry_L = False
        self._Phi = np.eye(self.n)
        self._phi_mode = self._phi_init    # "kept", "held" (until read), "dropped", "off": see apply_map
        self._pending: list = []        # error maps not yet multiplied into Phi (see apply_map)
        self._pending_ids: set = set()
        self._pending_bytes = 0
        self._span = 0.0                # time between the last two samples
        self._env_cache: tuple | None = None     # (amortised, (exact, noise)) bounds of the current sets
        if self._bound is not None:
            self._bound.reset()
        self._k = -1
        self._phase = 0  # sequence mode: offset of the design index, re-synced on mismatch
        self.resyncs = 0
        self._cycles.reset(t0)
        self._records.clear()
        self._tracker = EnvelopeTracker(self.designs[0].mu, self.e0, t0) if self._gains.paper_envelope else None
        # covariance: the family's own
        self._P = self.noise.P0.copy() if self.track_covariance else None
        self._gains.reset(self)

    @property
    def gains(self) -> Any:
        """The gain family in use (:mod:`switchobs_core.families`)."""
        return self._gains

    @property
    def kalman_fallback(self) -> str:
        """Why the Kalman table last left its cache ("" if it has not since the reset)."""
        return getattr(self._gains, "fallback", "")

    @property
    def kalman_departures(self) -> int:
        """Departures of the Kalman table from its cache since the reset (0 for other families)."""
        return getattr(self._gains, "departures", 0)

    @property
    def kalman_relocks(self) -> int:
        """Returns of the Kalman table to its cache since the reset (0 for other families)."""
        return getattr(self._gains, "relocks", 0)

    @property
    def x_hat(self) -> np.ndarray:
        """Current estimate ``x_hat(t)`` (a copy), shape (n,)."""
        return self._x.copy()

    @property
    def t(self) -> float:
        """Time of the last sample (or of the reset)."""
        return self._t

    @property
    def channel(self) -> int:
        """Active channel, 1-based (0 before the first sample)."""
        return self._channel

    @property
    def design_index(self) -> int:
        """Index into ``designs`` of the gains in use."""
        return (max(self._k, 0) + self._phase) % len(self.designs)

    @property
    def current_design(self) -> Any:
        """The CycleDesign whose gains are in use."""
        return self.designs[self.design_index]

    @property
    def completed_cycles(self) -> list[CycleRecord]:
        """The completed cycles, oldest first (at most ``max_records``)."""
        return list(self._records)

    @property
    def Phi(self) -> np.ndarray:
        """Error transition ``Phi(t, t0)``: the product of the steps' error maps ``E``.

        With innovation hold it is exact for sampled outputs (``x_tilde(t) = Phi x_tilde(t0)``
        with no noise and a known input); with measurement hold it is the error-to-error part.
        """
        return self._transition().copy()

    def _transition(self) -> np.ndarray:
        """``Phi`` with the held error maps multiplied in (in the order they were applied); from
        the first read on it is kept up to date at every step."""
        if self._phi_mode != "kept":
            if self._phi_mode == "off":
                raise InvalidArgument("Phi is not kept (transition=False); construct the observer with "
                                      "transition=True to read it")
            if self._phi_mode == "dropped":
                raise InvalidArgument(f"Phi was not read within {self._pending_max} samples of the reset and is no "
                                      "longer kept (its product costs O(n^3) per sample); construct the observer "
                                      "with transition=True to keep it")
            self._phi_mode = "kept"
        Phi = self._Phi
        for K, H in self._pending:
            if H is None:
                Phi = K @ Phi
            else:
                Phi -= K @ (H @ Phi)
        self._Phi = Phi
        self._pending.clear()
        self._pending_ids.clear()
        self._pending_bytes = 0
        return Phi

    def _hold_map(self, K: np.ndarray, H: np.ndarray | None) -> None:
        """Hold the map ``K`` (``H`` None) or ``I - K H`` for ``Phi`` (see :meth:`apply_map`)."""
        mode = self._phi_mode
        if mode == "kept":
            self._Phi = K @ self._Phi if H is None else self._Phi - K @ (H @ self._Phi)
            return
        if mode != "held":
            return
        self._pending.append((K, H))
        for X in (K, H):
            if X is not None and id(X) not in self._pending_ids:
                self._pending_ids.add(id(X))
                self._pending_bytes += X.nbytes
        if len(self._pending) > self._pending_max or self._pending_bytes > _PENDING_BYTES:
            self._phi_mode = "dropped"      # nobody read it: stop paying for it
            self._pending.clear()
            self._pending_ids.clear()
            self._pending_bytes = 0

    def apply_map(self, E: np.ndarray) -> None:
        """``Phi <- E Phi`` for a step with error map ``E``.

        ``Phi`` costs an n x n product per sample, so it is formed only for a reader
        (``transition``): by default the maps are held (references to cached matrices) and
        multiplied out at the first read of :attr:`Phi`, after which ``Phi`` is kept at every
        step; if it is not read within a budget of held maps (about ``2^31 / (2 n^3)`` of them,
        at most 65536, and 64 MiB of held arrays) it is no longer kept and reading it raises.
        ``transition=True`` keeps it from the start; ``False`` never."""
        self._hold_map(E, None)

    def apply_correction(self, K: np.ndarray, H: np.ndarray) -> None:
        """``Phi <- (I - K H) Phi`` for a correction with gain ``K`` and rows ``H`` (held as :meth:`apply_map`)."""
        self._hold_map(K, H)

    def rows_of(self, channel: int, rows: tuple | None) -> np.ndarray:
        """``H = C_channel[rows]`` (all rows for None)."""
        C = self.C[channel - 1]
        return C if rows is None else C[list(rows)]

    @property
    def cache(self) -> ZOHCache:
        """The ZOH step cache (``hits``, ``misses``)."""
        return self._cache

    # ------------------------------------------------------------------ samples
    def _rows(self, channel: int, rows: Any) -> tuple | None:
        if rows is None:
            return None
        try:
            r = tuple(int(i) for i in rows)
        except (TypeError, ValueError):
            raise InvalidArgument(f"rows must be a sequence of row indices; got {rows!r}") from None
        p = self.p[channel - 1]
        if not r or len(set(r)) != len(r) or min(r) < 0 or max(r) >= p:
            raise InvalidArgument(f"rows must be distinct indices in 0..{p - 1} of C_{channel}'s "
                                  f"rows; got {rows!r}")
        return None if r == tuple(range(p)) else r

    # ------------------------------------------------------------------ online
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
        dt = t - self._t
        if not dt >= 0:
            raise InvalidArgument(f"t = {t!r} is earlier than the observer's time {self._t!r} "
                                  "(samples must come in time order)" if dt < 0 else
                                  f"t must be a finite time; got {t!r}")
        if dt == math.inf:
            raise InvalidArgument(f"t must be a finite time; got {t!r}")
        if isinstance(channel, (bool, np.bool_)) or not isinstance(channel, (int, np.integer)) \
                or not 1 <= channel <= self.N:
            raise InvalidArgument(f"channel must be an integer in 1..{self.N}; got {channel!r}")
        y = np.asarray(y, dtype=float)
        if rows is not None:
            rows = self._rows(channel, rows)
        p = self.p[channel - 1] if rows is None else len(rows)
        if y.shape != (p,):
            y = y.reshape(-1)
            if y.size != p:
                raise InvalidArgument(f"y must have {p} entries for channel {channel}"
                                      f"{'' if rows is None else f' rows {rows}'}; got {y.size}")
        # one dot product checks both (hot path; 0.3 us vs 2 us for max|y|): y'y <= bound^2 is
        # False for NaN, for inf and for any entry beyond the bound
        if p and not float(y @ y) <= _MAX_SQ:
            if not np.isfinite(y).all():
                raise InvalidArgument(f"y has a non-finite entry: {y.tolist()}")
            raise InvalidArgument(f"y is too large (||y|| = {float(np.linalg.norm(y)):.3g} > {MAX_ABS_SAMPLE:g}): "
                                  "the update would overflow")
        if u is not None:
            u = np.asarray(u, dtype=float).reshape(-1)
            if u.size != self.m or not np.isfinite(u).all() or (u.size and np.abs(u).max() > MAX_ABS_SAMPLE):
                raise InvalidArgument(f"u must hold {self.m} finite entries of magnitude <= {MAX_ABS_SAMPLE:g}; "
                                      f"got {u.tolist()}")
        # 1. exact step over [t_prev, t]: x <- Phi x + GL v_held + GB u_held, v = nu or y
        #    (a family may fuse it with its correction: the Kalman table's one map per phase)
        fuse = self._gains.fuses(self)
        self._env_cache = None
        if dt > 0 and not fuse:
            self._step(dt)
        self._t = t
        self._span = dt
        # 2. switching instant
        if channel != self._channel:
            self._switch(t, channel)
        # 3. hold the new sample's input from t on; the family takes the sample (holds its
        #    innovation, or corrects)
        if u is not None:
            self._u = u
            self._u_zero = not u.any()
        self._gains.sample(self, t, dt if fuse else 0.0, channel, y, rows)
        return self._x

    def set_estimate(self, t: float, values: dict[int, float], variances: dict[int, float] | None = None) -> None:
        """Set entries of the estimate at time ``t >= obs.t`` (robot_localization's ``set_pose``).

        The observer first propagates to ``t`` exactly as between samples (the last innovation
        held), then ``x_hat[i] = values[i]``. Where the family keeps a covariance, ``P`` keeps
        its other entries and gets row/column ``i`` zeroed with ``P[i, i] = variances[i]`` (the
        entry's own variance, default the previous ``P[i, i]``); a Kalman table then runs the
        recursion online from that ``P`` and re-locks as after any departure. The exact bound
        no longer holds (the set entries' error is unknown): the caller must stop publishing it,
        as after :meth:`reset`.

        Raises
        ------
        InvalidArgument
            ``t`` before the observer's time or not finite, an index out of range, a value or
            a variance that is not finite (variances must be >= 0).
        """
        dt = float(t) - self._t
        if not (math.isfinite(dt) and dt >= 0):
            raise InvalidArgument(f"t = {t!r} must be a finite time >= the observer's time {self._t!r}")
        for i, v in list(values.items()) + list((variances or {}).items()):
            if not (isinstance(i, (int, np.integer)) and 0 <= i < self.n):
                raise InvalidArgument(f"state index {i!r} out of range 0..{self.n - 1}")
            if not math.isfinite(float(v)) or abs(float(v)) > MAX_ABS_SAMPLE:
                raise InvalidArgument(f"value {v!r} for state {i} must be finite (|v| <= {MAX_ABS_SAMPLE:g})")
        if any(float(v) < 0 for v in (variances or {}).values()):
            raise InvalidArgument("variances must be >= 0")
        # a cache of the recursion (the Kalman table) leaves it: the real covariance runs online
        self._gains.depart(self, "the state was set (set_estimate); running the Riccati recursion online")
        if dt > 0:
            self._env_cache = None
            self._step(dt)
            self._t = float(t)
        P = self.P
        x = self._x.copy()
        for i, v in values.items():
            x[i] = float(v)
        self._x = x
        if P is not None:
            P = P.copy()
            for i in set(values) | set(variances or {}):
                var = float((variances or {}).get(i, P[i, i]))
                P[i, :] = 0.0
                P[:, i] = 0.0
                P[i, i] = var
            self._P = P

    def _step(self, dt: float, *, covariance: bool = True) -> None:
        """Exact step over ``dt`` with the held innovation/measurement and input (step 1)."""
        e = self._cache.step(self._key, dt)
        xn = math.sqrt(float(self._x @ self._x))
        x = e.Phi @ self._x
        if self._entry_L:
            x += e.GL @ self._y
        if not self._u_zero:
            x += e.GB @ self._u
        self._x = x
        self.apply_map(e.E)
        if self._bound is not None:
            self._bound.step(e, dt, xn, math.sqrt(float(x @ x)), self._y if self._entry_L else None,
                             None if self._u_zero else self._u)
        if covariance and self._P is not None and self._gains.steps_covariance():
            self._propagate_covariance(e, dt)

    def _check_noise_max(self, noise_max: Any, hold: str) -> tuple[float, ...] | None:
        """``noise_max`` as one bound per channel (None: no bound declared)."""
        if noise_max is None:
            return None
        vals = np.atleast_1d(np.asarray(noise_max, dtype=object))
        if vals.ndim != 1 or vals.size not in (1, self.N):
            raise InvalidArgument(f"noise_max must be one number or {self.N} (one per channel); got {noise_max!r}")
        out = []
        for v in vals:
            if isinstance(v, (bool, np.bool_)) or not isinstance(v, (int, float, np.integer, np.floating)) \
                    or not (math.isfinite(float(v)) and 0 <= float(v) <= MAX_ABS_SAMPLE):
                raise InvalidArgument(f"noise_max must be finite numbers in [0, {MAX_ABS_SAMPLE:g}]; got {noise_max!r}")
            out.append(float(v))
        if not self.rounding_bound or hold != "innovation":
            raise InvalidArgument("noise_max needs rounding_bound=True and hold='innovation' "
                                  "(the noise bound extends the rounding-aware exact bound)")
        return tuple(out * self.N if len(out) == 1 else out)

    def _propagate_covariance(self, e: Any, dt: float) -> None:
        """Covariance of the error over one step (Joseph-free: the map is exact).

        ``P <- E P E' + Q_d(dt) + (Gamma L) R (Gamma L)'`` with ``E`` the step's error map,
        ``Q_d`` the van Loan discretisation of the process intensity, and the last term (LMI
        gains, innovation hold) the held measurement noise driven through ``Gamma L``; for the
        Kalman families ``E = e^{A dt}`` and the term is absent (the correction follows).
        """
        _, _, Q_d = self._dcache.get(dt)
        sp = sparse_transition(e) if e.E is e.Phi else None     # the open-loop map of a Kalman family
        P = (sp.sandwich(self._P) if sp is not None else e.E @ self._P @ e.E.T) + Q_d
        extra = self._gains.held_noise(self, e)
        if extra is not None:
            P += extra
        self._P = symmetrize(P)

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
        """
        return self._gains.covariance(self)

    def _switch(self, t: float, channel: int) -> None:
        """Bookkeeping at a switching instant (e:switching_instants), kept by the tracker."""
        cyc = self._cycles
        cyc.end_residence(t)
        if channel == 1:
            if cyc.cycle_start is not None:
                self._close_cycle(t)
            self._k += 1
        self._channel = channel
        d = self.current_design
        cyc.begin(t, channel, cyc.limits_for(d, channel))
        if self._tracker is not None:
            dead = design_dead_time(d)
            self._blind_until = t + dead - BLIND_TOL if dead else -math.inf
            self._tracker.switch(t, channel, d.kappa, d.eta, d.mu, dead_time=dead)

    def _close_cycle(self, t: float) -> None:
        di = self.design_index
        rec, resync = self._cycles.close_cycle(t, self._k, self.designs[di], di, self.promised[di],
                                               self.mode == "sequence")
        if resync:
            self._resync(rec.h)
        self._records.append(rec)

    def _resync(self, h: tuple) -> None:
        """Sequence mode: after a cycle that did not match its promise (a late start, a reset,
        a skipped cycle), find the first cycle of the sequence it did match and continue the
        sequence from there, so the next cycle uses the gains of the one after it. Repeated
        cycle types (the paper's (3, 0.6) twice) are resolved by the following mismatches."""
        K = len(self.promised)
        for j, c in enumerate(self.promised):
            if self._cycles.matches(h, c):
                self._phase = (j - self._k) % K
                self.resyncs += 1
                return

    @property
    def residence_violations(self) -> int:
        """Residences outside their designed interval since construction (kept by :meth:`reset`)."""
        return self._cycles.violations

    @property
    def residence_problem(self) -> str:
        """The statement of the residence that ended at the latest switching instant, if it
        broke its interval, else "" (compare ``residence_violations`` before and after an
        update to tell whether this update ended it)."""
        return self._cycles.problem_at_switch

    def residence(self) -> Residence | None:
        """The active channel's residence at the observer's time against the gains in use
        (None before the first sample); see :class:`~switchobs_core.runtime.cycles.CycleTracker`."""
        return self._cycles.residence(self._t, self.current_design)

    def predict(self, t: float, *, hold: bool = False) -> np.ndarray:
        """Prediction ``x_hat(t)`` for ``t >= obs.t`` without a sample; the state is unchanged.

        Parameters
        ----------
        t : float
        hold : bool
            False (default): open loop, ``xdot = A x + B u_held`` (no correction).
            True: what :meth:`update` would propagate, with the last sample held.

        Returns
        -------
        (n,) ndarray
        """
        dt = float(t) - self._t
        if not dt >= 0 or not math.isfinite(dt):
            raise InvalidArgument(f"t = {t!r} must be a finite time >= the observer's time {self._t!r}")
        if dt == 0:
            return self._x.copy()
        key = self._key if hold else ("open",)
        e = self._cache.step(key, dt)
        x = e.Phi @ self._x
        if key != ("open",) and self._entry_L:
            x += e.GL @ self._y
        if not self._u_zero:
            x += e.GB @ self._u
        return x

    def prior_covariance(self, t: float) -> np.ndarray | None:
        """The error covariance ``P^-(t)`` that :meth:`update` at ``t`` starts from (None when no
        covariance is kept): the last sample's ``P`` through the step's error map,
        ``E P E' + Q_d(dt)`` (plus the held measurement noise ``(Gamma L) R (Gamma L)'`` for LMI
        gains), as :meth:`_propagate_covariance` does; the state is unchanged. For the
        chi-square gate of :mod:`switchobs_core.runtime.consistency`."""
        P = self.P
        dt = float(t) - self._t
        if P is None or not (math.isfinite(dt) and dt >= 0):
            return None
        if dt == 0:
            return P
        e = self._cache.step(self._key, dt)
        _, _, Q_d = self._dcache.get(dt)
        P = e.E @ P @ e.E.T + Q_d
        extra = self._gains.held_noise(self, e)
        if extra is not None:
            P += extra
        return symmetrize(P)

    def prior(self, t: float) -> tuple[np.ndarray, np.ndarray | float, np.ndarray | float | None]:
        """What :meth:`update` at ``t`` starts from: the prediction ``x_hat(t)`` (the last sample
        held) and the rigorous sets of its error, ``(x_hat, exact, noise)``: each the shape
        matrix ``S`` of an ellipsoid ``{S^(1/2) u : ||u|| <= 1}`` holding the error
        (:class:`~switchobs_core.numerics.rounding.ErrorEllipsoid`, rounding included), or a float norm
        bound where no ellipsoid is kept; ``noise`` is None without a declared ``noise_max``. The
        state is unchanged.

        The innovation test of :mod:`switchobs_core.runtime.consistency` takes these: a sample at ``t``
        whose innovation exceeds what they allow proves the model broken for that sample.
        """
        x = self.predict(t, hold=True)
        dt = float(t) - self._t
        b = self._bound
        if b is None:
            env = self.envelope(t)
            return x, env.exact_bound, env.noise_bound
        if dt <= 0:
            return x, b.ell.S.copy(), None if b.ellv is None else b.ellv.S.copy()
        S, Sv = b.propagated(self._cache.step(self._key, dt), dt, math.sqrt(float(self._x @ self._x)),
                             math.sqrt(float(x @ x)), self._held_nu(), None if self._u_zero else self._u)
        return x, S, Sv

    def _held_nu(self) -> np.ndarray | None:
        """The held innovation of a held-innovation family (None: no gain held)."""
        return self._y if self._entry_L else None

    def envelope(self, t: float | None = None, *, amortised: bool | None = None) -> Envelope:
        """The paper's envelopes and bound, and the exact bound, at ``t`` (default: now).

        ``amortised`` (at the last sample's time, with the rounding-aware bound): the bounds read
        in O(n^2) between anchors (:mod:`switchobs_core.bounds.read`; rigorous, at most 1.062x the
        eigenvalue problem's, 1.02x in the median measured at n = 68), for a caller that
        publishes every sample. None (default): amortised from
        :data:`~switchobs_core.bounds.read.AMORTISED_MIN_N` states on (below, the eigenvalue
        problem is as cheap as the bookkeeping and is exact).

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
        dt = float(t) - self._t
        if not dt >= 0 or not math.isfinite(dt):
            raise InvalidArgument(f"t = {t!r} must be a finite time >= the observer's time {self._t!r}")
        step = self._cache.step(self._key, dt) if dt > 0 else None
        noisy = None
        b = self._bound
        if b is not None:       # rounding included (module switchobs_core.numerics.rounding)
            if amortised is None:
                amortised = self.n >= AMORTISED_MIN_N
            if step is None:    # the sets of the last sample: their bounds once per sample
                if self._env_cache is None or self._env_cache[0] != amortised:
                    self._env_cache = (amortised, b.bounds(amortised=amortised))
                exact, noisy = self._env_cache[1]
            else:
                xp = self.predict(float(t), hold=True)
                exact, noisy = b.bounds(*b.propagated(step, dt, math.sqrt(float(self._x @ self._x)),
                                                      math.sqrt(float(xp @ xp)), self._held_nu(),
                                                      None if self._u_zero else self._u))
        elif self.hold == "measurement":    # the error-to-error part, exact arithmetic (class Notes)
            Phi = self._transition()
            exact = float(np.linalg.norm(Phi if step is None else step.E @ Phi, 2) * self.e0)
        else:                               # rounding_bound=False: no bound is kept
            exact = math.inf
        if self._tracker is None:      # Kalman gains: the paper's envelope is for its LMI gains
            return Envelope(z=np.full(self.N, NOT_APPLICABLE), paper_bound=NOT_APPLICABLE,
                            exact_bound=exact, t=float(t), noise_bound=noisy)
        z = self._tracker.z(float(t))
        return Envelope(z=z, paper_bound=float(self.alpha * z.sum()), exact_bound=exact, t=float(t),
                        noise_bound=noisy)
