"""Schedule planning: the periodic schedule with the smallest steady Kalman covariance (beyond the paper).

The paper takes the cycle (tau, s) (e:tau_k, e:s_k) as given and designs gains for it. Here the
cycle itself is chosen. For a periodic schedule sampled at ``rate`` f, channel i active for
``h_i`` seconds per cycle in the visiting order 1..N (e:switching_instants), the cost is

.. math::

    J(h) = \\frac{1}{K} \\sum_{k=0}^{K-1} \\operatorname{tr}(W P^-_k)

the time average over the K samples of one period of the weighted trace of the *a-priori*
covariance ``P^-_k`` of the periodic steady state of the Kalman filter (the prior just before
the correction at sample k, the worst point of each sample interval; the periodic Riccati
solution of :func:`~switchobs_core.design.riccati.periodic_riccati`, the recursion the ``kalman``
gain family uses). ``W = diag(w)`` weights the states (default ``I``: the plain trace).

Integer sample counts. Active times are chosen on the sample grid, ``h_i = k_i / f`` with
integers ``k_i >= ceil(h_min f)`` and ``tau = sum h_i <= tau_max``, so every candidate has a
whole number ``K = sum k_i`` of samples per period and the cost is exact (no rounding of a
continuous schedule to samples). Samples are at ``t_k = k / f``; the sample at a switching
instant belongs to the channel that starts there (the rule of ``Schedule.channel_at``), so
channel 1 takes samples ``0..k_1-1``, channel 2 the next ``k_2``, and so on.

Dead time (``dead_time`` d > 0, :mod:`switchobs_core.model.schedule`): the first ``k_d`` samples of every
residence (those less than ``d`` after its switch, the rule of ``Schedule.blind_at``) measure
only the rows every channel shares, so ``k_i > k_d``. Without a dead time the optimum is the
fastest switching allowed; with one every switch costs ``k_d`` blind samples and the optimum
moves inside the box.

Undetectable schedules (an unstable mode never observed by the sampled periodic pair, the
test of :func:`~switchobs_core.design.kalman.check_detectable`) cost ``inf``, and so do schedules
beyond double precision (a channel unseen so long that the periodic covariance would span more
than :data:`~switchobs_core.design.precision.PRECISION_RANGE`, the test the Kalman design refuses
them with, :func:`~switchobs_core.design.precision.check_unseen`, or a cost pass whose periodic
prior does not come back, its digits lost): they are counted in
:attr:`ScheduleCost.beyond`, and a plan where every candidate is one of them is refused with
:class:`~switchobs_core.exceptions.PrecisionError`.

Optimiser (deterministic; no randomness):

1. a coarse grid of ``levels`` values per ``k_i`` between ``k_min`` and the largest count the
   ``tau_max`` budget allows (points beyond the budget skipped);
2. from the best grid point, a pattern search on the integer lattice: moves ``+-d e_i``
   (lengthen or shorten one channel) and ``+-d (e_i - e_j)`` (shift time from one channel to
   another, tau fixed), the best improving move taken; when none improves, ``d`` halves, down
   to 1. It stops at a point no unit neighbour improves: a local minimum of the integer
   problem (:func:`neighbours` lists the neighbourhood).

For N >= 3 the cyclic visiting order matters. ``schedule.py`` visits channels in the order
1..N, so the schedule :func:`plan_schedule` returns is in that order; with ``orders=True`` (N <= 4) the
other cyclic orders (channel 1 first) are optimised as well and reported for information (a
better order is used by renumbering the channels in the system file).

Cost evaluations are cached, and so is what candidate schedules share: the Riccati map of a run
of m samples of one channel, ``f^m`` (a triple of :mod:`switchobs_core.design.doubling`), for every m met so far. A
candidate's period map is its N runs' maps composed, its periodic prior of phase 0 the fixed
point by doubling, and its cost one pass over the runs with all priors of a run evaluated at
once: no sample-by-sample iteration over periods.
"""

from __future__ import annotations

import fnmatch
import itertools
import math
import sys
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..certificate import certify_cycle
from ..exceptions import DesignError, InvalidArgument, PrecisionError, UndetectableSchedule
from ..model.detectability import aliasing_free
from ..model.noise import NoiseModel, default_noise
from ..model.schedule import BLIND_TOL, Cycle, common_rows
from ..numerics.kalman_step import symmetrize
from ..ranges import check_size
from ..table.kalman import SamplePattern
from .doubling import RiccatiMap, fixed_point
from .kalman import check_detectable, design_kalman, sample_pattern
from .lmi import Designer
from .precision import beyond_precision, pattern_stretches
from .riccati import discretize, rel_change

__all__ = [
    "ScheduleCost",
    "PlanResult",
    "plan_schedule",
    "neighbours",
    "cycle_cost",
    "gain_reports",
    "parse_weights",
    "counts_to_cycle",
    "cost_map",
    "PLAN_RTOL",
]

#: Relative convergence tolerance of the periodic Riccati doubling for a cost evaluation.
PLAN_RTOL = 1e-11
#: Largest relative change of the prior of phase 0 over the pass that sums the cost.
PLAN_FLOOR = 1e-9


def parse_weights(text: str | Sequence[float] | None, system: Any) -> np.ndarray:
    """Diagonal state weights ``w`` (length n, >= 0, not all 0) from a comma list.

    Either n numbers (``1,1,0,0,...``), or state-label patterns (fnmatch globs on
    ``system.state_labels``), each optionally ``=weight`` (default 1); states no pattern
    matches get weight 0, e.g. ``agent*.p_*`` (agent positions only) or
    ``agent1.*=2,agent2.*``. ``None`` gives all ones (the plain trace).
    """
    n = int(system.n)
    if text is None:
        return np.ones(n)
    if not isinstance(text, str):
        w = np.asarray(text, dtype=float).reshape(-1)
    else:
        toks = [t.strip() for t in text.split(",") if t.strip()]
        if not toks:
            raise InvalidArgument("--weights is empty; give n numbers or state-label patterns")
        try:
            w = np.array([float(t) for t in toks])
        except ValueError:
            w = _weights_by_label(toks, system, n)
    if w.size != n:
        raise InvalidArgument(f"--weights needs n = {n} numbers (one per state); got {w.size}")
    if not np.all(np.isfinite(w)) or np.any(w < 0) or not np.any(w > 0):
        raise InvalidArgument(f"--weights must be finite, >= 0 and not all zero; got {w.tolist()}")
    return w


def _weights_by_label(toks: Sequence[str], system: Any, n: int) -> np.ndarray:
    """Weights from ``PATTERN[=W]`` tokens (fnmatch on the state labels; unmatched states 0)."""
    labels = list(getattr(system, "state_labels", ()) or [f"x{j}" for j in range(n)])
    w = np.zeros(n)
    for t in toks:
        pat, eq, val = t.partition("=")
        try:
            v = float(val) if eq else 1.0
        except ValueError:
            raise InvalidArgument(f"--weights: bad weight in {t!r} (use PATTERN=NUMBER)") from None
        hit = [j for j, lab in enumerate(labels) if fnmatch.fnmatchcase(lab, pat.strip())]
        if not hit:
            raise InvalidArgument(f"--weights: pattern {pat.strip()!r} matches no state; states: {', '.join(labels)}")
        w[hit] = v
    return w


def counts_to_cycle(counts: Sequence[int], rate: float, dead_time: float = 0.0) -> Cycle:
    """The cycle ``h_i = k_i / rate`` (with blind intervals of ``dead_time`` s after each switch)."""
    return Cycle([int(k) / rate for k in counts], dead_time)


def blind_samples(dead_time: float, rate: float) -> int:
    """``k_d``: samples at ``j / rate`` (j = 0, 1, ...) into a residence that are blind, i.e.
    ``j / rate < d - BLIND_TOL`` (the rule of ``Schedule.blind_at``)."""
    if not dead_time:
        return 0
    return max(0, math.ceil((dead_time - BLIND_TOL) * rate - 1e-9))


def neighbours(counts: Sequence[int], step: int = 1) -> list[tuple[int, ...]]:
    """Lattice neighbours of ``counts``: ``+-step e_i`` and ``step (e_i - e_j)``, i != j (no bounds)."""
    k = tuple(int(v) for v in counts)
    N = len(k)
    out = []
    for i in range(N):
        for sgn in (1, -1):
            out.append(tuple(v + sgn * step if j == i else v for j, v in enumerate(k)))
    for i in range(N):
        for j in range(N):
            if i != j:
                out.append(tuple(v + step if m == i else v - step if m == j else v for m, v in enumerate(k)))
    return out


class _Run:
    """Powers ``f^j`` (j = 0, 1, ...) of the one-sample Riccati map ``f = (Phi, H' R^{-1} H, Q_d)`` of
    one channel (blind or not), grown on demand and kept across candidate schedules, with what the
    cost needs of each: ``tr(W Q_j)`` and ``B_j = A_j' W A_j``, so that
    ``tr(W f^j(X)) = tr(W Q_j) + sum(B_j * (X (I + G_j X)^{-1}))`` for many j at once."""

    def __init__(self, Phi: np.ndarray, H: np.ndarray, R: np.ndarray, Qd: np.ndarray, w: np.ndarray) -> None:
        n = Phi.shape[0]
        self.f = RiccatiMap(Phi, symmetrize(H.T @ np.linalg.solve(R, H)), Qd)
        self.w = w
        self.A = [np.eye(n)]
        self.G = [np.zeros((n, n))]
        self.Q = [np.zeros((n, n))]
        self._tQ = np.zeros(0)

    def grow(self, m: int) -> None:
        """Make ``f^j`` available for j <= m (``f^{j+1} = f o f^j``)."""
        while len(self.A) <= m:
            g = RiccatiMap(self.A[-1], self.G[-1], self.Q[-1]).then(self.f)
            self.A.append(g.A)
            self.G.append(g.G)
            self.Q.append(g.Q)
        if len(self._tQ) < len(self.A):
            W = self.w
            self._tQ = np.array([W @ np.diagonal(Q) for Q in self.Q])
            self._B = np.stack([(A.T * W) @ A for A in self.A])
            self._Gs = np.stack(self.G)

    def power(self, m: int) -> RiccatiMap:
        """``f^m``."""
        self.grow(m)
        return RiccatiMap(self.A[m], self.G[m], self.Q[m])

    def trace_sum(self, X: np.ndarray, m: int) -> float:
        """``sum_{j < m} tr(W f^j(X))``: the weighted traces of the m priors of a run from prior X."""
        self.grow(m)
        n = X.shape[0]
        # f^j(X) = Q_j + A_j Y_j A_j' with Y_j = (I + X G_j)^{-1} X
        Y = np.linalg.solve(np.eye(n) + X @ self._Gs[:m], np.broadcast_to(X, (m, n, n)))
        return float(self._tQ[:m].sum() + np.einsum("jab,jba->", self._B[:m], Y))


class ScheduleCost:
    """Cost of periodic schedules of one system, noise model, rate and weights (module docstring).

    ``J = ScheduleCost(system, rate, noise, weights); J(counts)`` (cached), or
    ``J.of_channels(channels)`` for any sample pattern (channel of each sample of one period).
    """

    def __init__(self, system: Any, rate: float, noise: NoiseModel | None = None,
                 weights: Any = None, *, rtol: float = PLAN_RTOL, dead_time: float = 0.0) -> None:
        if isinstance(rate, bool) or not isinstance(rate, (int, float, np.integer, np.floating)) or not (
                math.isfinite(rate) and rate > 0):
            raise InvalidArgument(f"rate must be a finite number > 0 (Hz); got {rate!r}")
        self.system = system
        self.rate = float(rate)
        self.noise = default_noise(system) if noise is None else noise
        if not isinstance(self.noise, NoiseModel):
            raise InvalidArgument(f"noise must be a NoiseModel; got {type(self.noise).__name__}")
        self.noise.check_system(system)
        self.w = parse_weights(weights, system)
        self.rtol = float(rtol)
        A = np.asarray(system.A, dtype=float)
        self.Phi, _, self.Qd = discretize(A, np.asarray(system.B, dtype=float), self.noise.Q_c, 1.0 / self.rate)
        self._H = [np.asarray(C, dtype=float) for C in system.C]
        self._R = [self.noise.R(i + 1) for i in range(system.N)]
        d = float(dead_time)
        if not (math.isfinite(d) and d >= 0):
            raise InvalidArgument(f"dead_time must be a finite number of seconds >= 0; got {dead_time!r}")
        self.dead_time = d
        self.k_dead = blind_samples(d, self.rate)
        rows = list(common_rows(system.C))
        self._Hb = [H[rows] for H in self._H]
        self._Rb = [self.noise.R(i + 1, rows) for i in range(system.N)]
        self._runs: dict[tuple[int, bool], _Run] = {}
        self._detect: dict[frozenset, bool] = {}
        self.cache: dict[tuple[int, ...], float] = {}
        self.evaluations = 0
        #: Candidates beyond double precision so far, and the refusal of the first one.
        self.beyond = 0
        self.beyond_reason = ""

    def channels(self, counts: Sequence[int], order: Sequence[int] | None = None) -> tuple[int, ...]:
        """Channel of every sample of one period: ``k_i`` samples of each channel, in ``order``."""
        order = tuple(range(1, len(counts) + 1)) if order is None else tuple(order)
        return tuple(c for c in order for _ in range(int(counts[c - 1])))

    def blind(self, counts: Sequence[int], order: Sequence[int] | None = None) -> tuple[bool, ...]:
        """Whether each sample of :meth:`channels` is blind (the first ``k_d`` of every residence)."""
        order = tuple(range(1, len(counts) + 1)) if order is None else tuple(order)
        return tuple(j < self.k_dead for c in order for j in range(int(counts[c - 1])))

    def _run(self, c: int, b: bool) -> _Run:
        r = self._runs.get((c, b))
        if r is None:
            H, R = (self._Hb[c - 1], self._Rb[c - 1]) if b else (self._H[c - 1], self._R[c - 1])
            r = self._runs[(c, b)] = _Run(self.Phi, H, R, self.Qd, self.w)
        return r

    def _detectable(self, pattern: SamplePattern) -> bool:
        """:func:`~switchobs_core.design.kalman.check_detectable`, cached by the set of (channel, blind) pairs
        measured when the period aliases no two modes (:func:`~switchobs_core.model.detectability.aliasing_free`)."""
        key = None
        if aliasing_free(self.system.A, pattern.K / self.rate):
            key = frozenset(zip(pattern.channels, pattern.blind or (False,) * pattern.K))
            ok = self._detect.get(key)
            if ok is not None:
                return ok
        try:
            check_detectable(self.system, pattern)
            ok = True
        except UndetectableSchedule:
            ok = False
        if key is not None:
            self._detect[key] = ok
        return ok

    def of_channels(self, channels: Sequence[int], cycles: Sequence[Cycle] = (),
                    blind: Sequence[bool] = ()) -> float:
        """Cost of the periodic sample pattern ``channels`` (``blind[k]``: sample k measures only the
        shared rows; inf if undetectable).

        The period's samples form runs of one channel (blind or not); the map of a run of m
        samples is ``f^m``, kept across candidates (:class:`_Run`). 1. the period map, the runs'
        maps composed; 2. its fixed point by doubling (:func:`~switchobs_core.design.doubling.fixed_point`):
        the prior of phase 0; 3. the mean weighted trace over the runs from there, all priors of a
        run at once; the prior of phase 0 must come back within ``PLAN_FLOOR`` (else the pass
        repeats from where it ended). A pattern beyond double precision (before step 1, or a pass
        that never comes back) costs inf and is counted in :attr:`beyond`."""
        K = len(channels)
        blind = tuple(bool(b) for b in blind) if any(blind) else ()
        pattern = SamplePattern(self.rate, tuple(cycles) or (Cycle([1.0] * self.system.N),), 1,
                                tuple(int(c) for c in channels), (), blind)
        if not self._detectable(pattern):
            return math.inf
        what = f"the schedule of {K} samples ({K / self.rate:g} s) at {self.rate:g} Hz"
        why = beyond_precision(self.system, pattern_stretches(pattern.channels, blind, self.rate, self.system.N),
                               power=2, what=what)
        if not why:
            # runs of equal (channel, blind)
            runs: list[tuple[_Run, int]] = []
            for key, grp in itertools.groupby(zip(channels, blind or (False,) * K)):
                runs.append((self._run(int(key[0]), bool(key[1])), sum(1 for _ in grp)))
            try:
                return self._cost(runs, K, what)
            except PrecisionError as err:
                why = str(err)
        self.beyond += 1
        self.beyond_reason = self.beyond_reason or why
        return math.inf

    def _cost(self, runs: list, K: int, what: str) -> float:
        """Steps 1-3 of :meth:`of_channels` over the runs of one period of ``K`` samples."""
        # 1. period map; 2. fixed point
        F = runs[0][0].power(runs[0][1])
        for r, m in runs[1:]:
            F = F.then(r.power(m))
        X, _, _ = fixed_point(F, rtol=self.rtol)
        self.evaluations += 1
        # 3. J = (1/K) sum_k tr(W P^-_k), W = diag(w), run by run
        for _ in range(4):
            total, Y = 0.0, X
            for r, m in runs:
                total += r.trace_sum(Y, m)
                Y = r.power(m)(Y)
            if rel_change(Y, X) <= PLAN_FLOOR:
                break
            X = Y
        else:
            raise PrecisionError(f"{what} is beyond double precision: its periodic Riccati solution does not come back "
                                 f"within {PLAN_FLOOR:g} over a period (the covariance spans more than its digits "
                                 "resolve); shorten the residences or the cycle")
        return total / K

    def __call__(self, counts: Sequence[int], order: Sequence[int] | None = None) -> float:
        key = tuple(int(k) for k in counts) + (() if order is None else tuple(order))
        J = self.cache.get(key)
        if J is None:
            if min(int(k) for k in counts) <= self.k_dead:      # a residence no longer than the dead time
                J = self.cache[key] = math.inf
                return J
            J = self.cache[key] = self.of_channels(self.channels(counts, order),
                                                   (counts_to_cycle(counts, self.rate, self.dead_time),),
                                                   self.blind(counts, order))
        return J


@dataclass
class PlanResult:
    """Outcome of :func:`plan_schedule`: the schedule ``counts`` (samples per channel), its cycle and cost.

    ``alternatives`` lists other cyclic visiting orders (N >= 3 with ``orders=True``):
    ``{"order": (...), "counts": (...), "cost": J}``.
    """

    rate: float
    counts: tuple[int, ...]
    cost: float
    k_min: int
    k_total_max: int
    evaluations: int
    local_minimum: bool
    weights: np.ndarray
    alternatives: list[dict] = field(default_factory=list)
    dead_time: float = 0.0

    @property
    def cycle(self) -> Cycle:
        return counts_to_cycle(self.counts, self.rate, self.dead_time)

    @property
    def h(self) -> tuple[float, ...]:
        return self.cycle.h

    @property
    def tau(self) -> float:
        return sum(self.counts) / self.rate


def _grid_levels(lo: int, hi: int, levels: int) -> list[int]:
    if hi <= lo:
        return [lo]
    return sorted({int(round(v)) for v in np.linspace(lo, hi, max(2, levels))})


def _bar(progress: bool | None, desc: str):
    from tqdm import tqdm

    return tqdm(total=None, desc=desc, unit="eval", leave=False, file=sys.stderr,
                disable=(None if progress is None else not progress))


def _search(J: ScheduleCost, N: int, kmin: int, kmax_total: int, levels: int, order, bar) -> tuple:
    """Coarse grid then pattern search (module docstring); returns (counts, cost, local_min)."""
    def ok(k):
        return all(v >= kmin for v in k) and sum(k) <= kmax_total

    def f(k):
        before = J.evaluations
        val = J(k, order)
        if J.evaluations != before:
            bar.update(1)
        return val

    top = kmax_total - (N - 1) * kmin
    lv = _grid_levels(kmin, top, levels)
    best, best_J = None, math.inf
    for k in itertools.product(lv, repeat=N):
        if ok(k):
            val = f(k)
            if val < best_J or best is None:
                best, best_J = k, val
    d = max(1, (lv[1] - lv[0]) // 2 if len(lv) > 1 else 1)
    while True:
        moved = True
        while moved:
            moved = False
            cand = [k for k in neighbours(best, d) if ok(k)]
            if not cand:
                break
            vals = [f(k) for k in cand]
            i = int(np.argmin(vals))
            if vals[i] < best_J:
                best, best_J, moved = cand[i], vals[i], True
                bar.set_postfix_str(f"best {best} cost {best_J:.4g}")
        if d == 1:
            break
        d //= 2
    local = all(not ok(k) or J(k, order) >= best_J for k in neighbours(best, 1))
    return tuple(best), best_J, local


def plan_schedule(
    system: Any,
    rate: float,
    noise: NoiseModel | None = None,
    *,
    weights: Any = None,
    h_min: float = 0.5,
    tau_max: float = 4.0,
    levels: int | None = None,
    orders: bool = True,
    progress: bool | None = None,
    cost: ScheduleCost | None = None,
) -> PlanResult:
    """The periodic schedule of least weighted mean prior covariance trace (module docstring).

    ``res = plan_schedule(paper_system(), 100.0, h_min=0.5, tau_max=4.0)``; ``res.cycle``, ``res.cost``.

    Raises
    ------
    InvalidArgument
        Bad rate, ``h_min`` or ``tau_max``, or no schedule fits (``N ceil(h_min f) > tau_max f``).
    DesignError
        Every candidate is undetectable (cost inf everywhere).
    PrecisionError
        Every candidate is undetectable or beyond double precision, some of them the latter.
    """
    for name, v in (("h_min", h_min), ("tau_max", tau_max)):
        if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)) or not math.isfinite(v):
            raise InvalidArgument(f"{name} must be a finite number of seconds; got {v!r}")
    if h_min < 0 or tau_max <= 0:
        raise InvalidArgument(f"need h_min >= 0 and tau_max > 0; got h_min = {h_min}, tau_max = {tau_max}")
    J = cost if cost is not None else ScheduleCost(system, rate, noise, weights)
    f = J.rate
    N = int(system.N)
    kmin = max(1, math.ceil(h_min * f - 1e-9), J.k_dead + 1)
    kmax_total = math.floor(tau_max * f + 1e-9)
    n = int(system.n)
    check_size(kmax_total, 8 * (5 * n * n + 2 * n * n) + 1024,
               f"periods of up to {kmax_total:.3g} samples (tau_max {tau_max:g} s at {f:g} Hz)",
               "lower --rate or --tau-max")
    if N * kmin > kmax_total:
        raise InvalidArgument(
            f"no schedule fits: {N} channels x h_min {h_min:g} s need tau >= {N * kmin / f:g} s > "
            f"tau_max {tau_max:g} s at {f:g} Hz; raise --tau-max or lower --h-min")
    if levels is None:
        levels = {2: 6, 3: 4}.get(N, 3)
    natural = tuple(range(1, N + 1))
    all_orders = [natural]
    if orders and 3 <= N <= 4:
        all_orders += [(1,) + p for p in itertools.permutations(range(2, N + 1)) if (1,) + p != natural]
    bar = _bar(progress, "plan")
    try:
        results = []
        for order in all_orders:
            counts, val, local = _search(J, N, kmin, kmax_total, levels, None if order == natural else order, bar)
            results.append((order, counts, val, local))
    finally:
        bar.close()
    order, counts, val, local = results[0]
    if not math.isfinite(val) and J.beyond:
        raise PrecisionError(
            f"every schedule with h_i >= {h_min:g} s and tau <= {tau_max:g} s tried at {f:g} Hz is undetectable or "
            f"beyond double precision ({J.beyond} of them, e.g. {J.beyond_reason}); lower --tau-max or --h-min")
    if not math.isfinite(val):
        raise DesignError(
            f"every schedule with h_i >= {h_min:g} s and tau <= {tau_max:g} s tried at {f:g} Hz is undetectable "
            "(some unstable mode is never observed); lengthen tau_max")
    alts = [{"order": o, "counts": c, "cost": v, "local_minimum": lm} for o, c, v, lm in results[1:]]
    return PlanResult(f, counts, val, kmin, kmax_total, J.evaluations, local, J.w, alts, J.dead_time)


def cost_map(J: ScheduleCost, taus: Sequence[float], s_values: Sequence[float], kmin: int = 1,
             progress: bool | None = None) -> np.ndarray:
    """Cost over a (tau, s) grid of a two-channel system (counts rounded to the sample grid).

    NaN where a rounded active time is below ``kmin`` samples. Array (len(taus), len(s_values)).
    """
    if J.system.N != 2:
        raise InvalidArgument("the (tau, s) cost map is defined for two channels")
    out = np.full((len(taus), len(s_values)), np.nan)
    bar = _bar(progress, "map")
    try:
        for a, tau in enumerate(taus):
            K = int(round(tau * J.rate))
            for b, s in enumerate(s_values):
                k1 = int(round(s * K))
                if k1 >= kmin and K - k1 >= kmin:
                    out[a, b] = J((k1, K - k1))
                bar.update(1)
    finally:
        bar.close()
    return out


def cycle_cost(J: ScheduleCost, cycle: Cycle) -> float:
    """Cost of an arbitrary cycle at ``J.rate`` through the sample pattern the ``kalman`` design uses
    (:func:`~switchobs_core.design.kalman.sample_pattern`, which may take several cycles per period)."""
    pat = sample_pattern(cycle, J.rate)
    return J.of_channels(pat.channels, pat.cycles, pat.blind)


def gain_reports(system: Any, cycle: Cycle, rate: float, noise: NoiseModel, *, delta: float = 0.99) -> dict:
    """For the planned cycle: the paper's LMI design (eta_min, feasibility) and the certified decay
    rates of both gain families.

    * ``lmi``: :meth:`Designer.design` (Theorem t:main conditions e:eta1_bound, e:eta2_bound,
      eta_min from e:eta1_fixed); certified rate ``-ln(rho)/tau`` of the exact cycle transition
      ``Phi = prod expm((A - L_i C_i) h_i)`` (e:xtilde_dyn_piecewise; the paper's
      continuous-output setting, :func:`~switchobs_core.certificate.certify_cycle`).
      ``{"feasible": False, "reason": ...}`` when the design fails.
    * ``kalman``: :func:`~switchobs_core.design.kalman.design_kalman` at ``rate``; certified rate
      ``-ln(rho)/T`` of the period's noise-free error map ``prod (I - K_k H_k) Phi``
      (e:error_dynamics sampled), T the period; plus whether its sample pattern equals the
      plan's (no tie at a switching instant resolved differently in floating point).
    """
    out: dict[str, Any] = {}
    try:
        d = Designer(system, delta=delta).design(cycle)
        cert = certify_cycle(system, d)
        rho = cert.spectral_radius
        out["lmi"] = {
            "feasible": True, "eta_min": list(d.eta_min), "eta": list(d.eta), "f": list(d.f),
            "paper_condition_holds": bool(d.certified), "spectral_radius": rho,
            "certified_rate": _rate(rho, cycle.tau),
        }
    except DesignError as err:
        out["lmi"] = {"feasible": False, "reason": str(err)}
    try:
        kd = design_kalman(system, cycle, rate, noise, max_startup=0)      # the period's map only
        out["kalman"] = {
            "spectral_radius": kd.rho, "norm": kd.norm, "period": kd.pattern.period,
            "certified_rate": _rate(kd.rho, kd.pattern.period), "channels": kd.pattern.channels,
            "ties": list(kd.pattern.ties),
        }
    except DesignError as err:
        out["kalman"] = {"feasible": False, "reason": str(err)}
    return out


def _rate(rho: float, T: float) -> float:
    """Certified exponential decay rate ``-ln(rho) / T`` (inf for rho = 0)."""
    return math.inf if rho <= 0 else -math.log(rho) / T
