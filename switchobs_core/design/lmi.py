"""Decay-rate selection (Sec. ``s:LMI_Gain``): eta_min, cycle designs, robust designs.

For channel i active h_i seconds and inactive u_i seconds per cycle, Theorem ``t:main``
needs (e:eta1_bound, e:eta2_bound, written for N channels)

    g_i(eta) = eta h_i - mu_i u_i - ln(kappa_i(eta) / delta_i) >= 0.

eta_min_i is the smallest eta >= 0 with g_i(eta) >= 0 (the fixed point e:eta1_fixed).
kappa_i(eta) comes from one :class:`~switchobs_core.design.synthesis.KappaCurve` per channel
(it does not depend on the cycle), so designs of many cycles share SDP solves.

Root finding: g_i is scanned on the fixed grid ETA_GRID = {0} U {0.05 * 1.12^k} (the
same points for every cycle, so their SDPs are cached) up to the first grid point with
g >= 0; then Brent's method on the exact g (one SDP per new eta, cached) brackets the
root to 1e-7. The smallest root is found at grid resolution (12 %); g is smooth and,
when ln kappa is concave (the paper's model), convex, so it has one root past 0.

Selected rates: eta_i = max(eta_min_i + margin, ETA_FLOOR) with an absolute or relative
margin; the final gain is synthesized and verified at eta_i, and the paper's factor
f_ii = kappa_i exp(mu_i u_i - eta_i h_i) is computed with the verified kappa. A design
whose f_ii exceeds delta_i is refused (increase the margin), unless eta was given
explicitly, in which case it is recorded with ``certified = False``.

Robust design (assumption A2, beyond the paper): if every residence time lies in
[h_min, h_max], channel i is active at least h_min and inactive at most (N - 1) h_max
per cycle (at least (N - 1) h_min when mu_i < 0). Designing eta_i for that worst case
makes f_ii <= delta_i for every admissible cycle, so one gain set serves all schedules.

Precision. A cycle (or box) that leaves a channel unseen so long that the error of what only it
sees grows past :data:`~switchobs_core.design.precision.PRECISION_RANGE` meanwhile is refused
before any SDP (:class:`~switchobs_core.exceptions.PrecisionError`): the cycle's error map
passes through that growth, and its entries keep ``u g`` relative accuracy
(:mod:`switchobs_core.design.precision`).

Paper labels (``e:...``, ``t:...``) resolve to numbers in ``docs/equations.md``.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from ..certificate import cycle_factor
from ..exceptions import DesignError, InfeasibleDesign, InvalidArgument, ScheduleError
from ..model.decomposition import Decomposition
from ..model.schedule import Cycle, check_cycle_horizon
from ..model.system import LTISystem
from ..table.gains import ChannelGain, CycleDesign, GainTable
from ..validation import as_finite
from .precision import check_unseen, cycle_stretches, cycles_label
from .synthesis import KAPPA_GRID, THETA_SLACK, KappaCurve, LMISynthesizer

if TYPE_CHECKING:
    from scipy.interpolate import PchipInterpolator

__all__ = [
    "Margin",
    "ChannelDesigner",
    "Designer",
    "design_cycle",
    "design_table",
    "ETA_GRID",
    "ETA_FLOOR",
]

#: Fixed scan grid of eta (shared by all cycles so SDP solves are cached).
ETA_GRID = KAPPA_GRID
#: Smallest selected decay rate (Theorem t:main needs eta > 0).
ETA_FLOOR = 1e-3


@dataclass(frozen=True)
class Margin:
    """How far above eta_min the selected rate lies: ``absolute`` (eta_min + value) or
    ``relative`` (eta_min * (1 + value)).

    ``Margin.parse("0.1")`` is absolute, ``Margin.parse("5%")`` relative.
    """

    kind: str = "relative"
    value: float = 0.05

    def __post_init__(self) -> None:
        if self.kind not in ("absolute", "relative"):
            raise InvalidArgument(f"margin kind must be 'absolute' or 'relative'; got {self.kind!r}")
        v = as_finite(self.value, "margin value")
        if v < 0:
            raise InvalidArgument(f"margin value must be >= 0; got {v}")

    @classmethod
    def parse(cls, text: str | float) -> Margin:
        s = str(text).strip()
        try:
            if s.endswith("%"):
                return cls("relative", float(s[:-1]) / 100)
            return cls("absolute", float(s))
        except ValueError:
            raise InvalidArgument(f"cannot parse margin {text!r}; use e.g. 0.1 (absolute) or 5% (relative)") from None

    def apply(self, eta_min: float) -> float:
        eta = eta_min + self.value if self.kind == "absolute" else eta_min * (1 + self.value)
        return max(eta, ETA_FLOOR)

    def to_dict(self) -> dict:
        return {"kind": self.kind, "value": self.value}


class ChannelDesigner:
    """Per-channel design machinery: decomposition, mu_i, the SDP and its kappa curve."""

    def __init__(self, decomp: Decomposition, *, solver: str = "CLARABEL") -> None:
        self.decomp = decomp
        self.mu = decomp.mu
        self.synth = LMISynthesizer(decomp.A_o, decomp.C_o, solver=solver)
        self.curve = KappaCurve(self.synth)
        self._interp: tuple[int, PchipInterpolator] | None = None  # (grid points used, interpolant)

    def g(
        self, eta: float, active: float, inactive: float, delta: float, kappa: Callable[[float], float] | None = None
    ) -> float:
        """g(eta) = eta h - mu u - ln(kappa(eta) / delta) (>= 0 iff e:eta1_bound holds)."""
        k = (kappa or self.curve.kappa)(eta)
        return eta * active - self.mu * inactive - math.log(k / delta)

    def eta_min(self, active: float, inactive: float, delta: float, *, what: str = "") -> float:
        """Smallest eta >= 0 with g(eta) >= 0 (grid scan, then Brent on the exact g).

        Since kappa >= 1, g(eta) <= eta h - mu u + ln(delta); if that bound is negative
        at the largest grid rate, no rate qualifies and no SDP is solved.
        """
        top = float(ETA_GRID[-1])
        if top * active - self.mu * inactive + math.log(delta) < 0:
            f_best = math.exp(self.mu * inactive - top * active)
            raise InfeasibleDesign(
                f"{what}no decay rate up to {top:.4g} satisfies the cycle condition (active {active:g} s, "
                f"inactive {inactive:g} s, delta {delta:g}): even with kappa = 1, f = exp(mu u - eta h) = "
                f"{f_best:.3g} > delta at eta = {top:.4g}; lengthen the active time"
            )
        prev = None
        for eta in ETA_GRID:
            try:
                val = self.g(eta, active, inactive, delta)
            except DesignError as err:
                raise InfeasibleDesign(
                    f"{what}no decay rate up to {prev or 0.0:.4g} satisfies the cycle condition (active "
                    f"{active:g} s, inactive {inactive:g} s, delta {delta:g}), and the SDP fails beyond "
                    f"eta = {eta:.4g} ({err}); lengthen the active time"
                ) from None
            if val >= 0:
                if prev is None:
                    return 0.0
                from scipy.optimize import brentq  # only a design needs it: not imported at start-up
                try:
                    return float(brentq(lambda e: self.g(e, active, inactive, delta), prev, eta, xtol=1e-9, rtol=1e-10))
                except DesignError as err:
                    raise DesignError(
                        f"{what}{err} (while refining eta_min between {prev:.4g} and {eta:.4g})"
                    ) from None
            prev = eta
        raise InfeasibleDesign(
            f"{what}no decay rate up to {ETA_GRID[-1]:.3g} satisfies the cycle condition "
            f"(active {active:g} s, inactive {inactive:g} s, delta {delta:g}); lengthen the active time"
        )

    def eta_min_interp(self, active: float, inactive: float, delta: float) -> float:
        """eta_min from the monotone interpolant of the cached kappa curve (for maps and figures).

        The grid is extended with exact SDPs as far as needed; between grid points ln kappa
        is interpolated (PCHIP), so the result is approximate (not used for gains). NaN
        when no grid rate satisfies the condition or the SDP fails before one does (the
        point is not designable; figures draw it as such).
        """
        prev = None
        for eta in ETA_GRID:
            try:
                if self.g(eta, active, inactive, delta) >= 0:
                    break
            except DesignError:
                return float("nan")
            prev = eta
        else:
            return float("nan")
        if prev is None:
            return 0.0
        from scipy.interpolate import PchipInterpolator
        from scipy.optimize import brentq

        e, k = self.curve.points()
        if self._interp is None or self._interp[0] != e.size:  # rebuilt only when the curve grew
            self._interp = (e.size, PchipInterpolator(e, np.log(k)))
        interp = self._interp[1]

        def kap(x: float) -> float:
            return math.exp(float(interp(x)))

        return float(brentq(lambda x: self.g(x, active, inactive, delta, kap), prev, eta, xtol=1e-7))


class Designer:
    """Designs gain sets for one system; caches the kappa curves across all its designs.

    ``des = Designer(sys, delta=0.99, margin=Margin("relative", 0.05))``
    """

    def __init__(
        self,
        system: LTISystem,
        *,
        delta: float | Sequence[float] = 0.99,
        margin: Margin | None = None,
        solver: str = "CLARABEL",
    ) -> None:
        if not hasattr(system, "decompositions") or not hasattr(system, "N"):
            raise InvalidArgument(f"system must be an LTISystem (load_system(...)); got {system!r}")
        self.system = system
        self.delta = _deltas(delta, system.N)
        self.margin = margin or Margin()
        self.solver = solver.upper()
        self.channels = [ChannelDesigner(d, solver=solver) for d in system.decompositions]

    def eta_min(self, cycle: Cycle) -> tuple[float, ...]:
        """(eta_min_1, ..., eta_min_N) of a cycle (e:eta1_fixed, e:eta2_fixed)."""
        self._check_cycle(cycle)
        return tuple(
            ch.eta_min(cycle.active(i + 1), cycle.inactive(i + 1), self.delta[i],
                       what=f"cycle {cycle.label()}, channel {i + 1}: ")
            for i, ch in enumerate(self.channels)
        )

    def _eta_min_or_none(self, cycle: Cycle, i: int) -> float | None:
        try:
            return self.channels[i].eta_min(cycle.active(i + 1), cycle.inactive(i + 1), self.delta[i])
        except InfeasibleDesign:
            return None

    def _check_cycle(self, cycle: Cycle) -> None:
        if not isinstance(cycle, Cycle):
            raise InvalidArgument(f"cycle must be a Cycle; got {type(cycle).__name__}")
        if cycle.N != self.system.N:
            raise ScheduleError(f"cycle {cycle.label()} has {cycle.N} channels; the system has {self.system.N}")
        check_cycle_horizon(self.system.A, cycle)
        check_unseen(self.system, cycle_stretches(cycle.h, cycle.dead_time), power=1,
                     what=f"the LMI design of {cycles_label([cycle])}")

    def _channel_gain(self, i: int, eta: float, eta_min: float | None, active: float, inactive: float) -> ChannelGain:
        ch = self.channels[i]
        g = ch.synth.gain(eta)
        T_o = ch.decomp.T_o
        L = T_o @ g.L_o  # L_i = T_i [L_o; 0] (e:L_original)
        f = cycle_factor(g.kappa, ch.mu, eta, active, inactive)
        return ChannelGain(
            eta_min=eta_min,
            eta=eta,
            kappa=g.kappa,
            kappa_star=g.kappa_star,
            mu=ch.mu,
            active=active,
            inactive=inactive,
            f=f,
            eta_verified=g.eta_verified,
            abscissa=g.abscissa,
            L_o=g.L_o,
            L=L,
            P=g.P,
        )

    def _finish(
        self, kind: str, cycle: Cycle | None, bounds, gains: list[ChannelGain], explicit: bool, what: str
    ) -> CycleDesign:
        d = CycleDesign(kind=kind, cycle=cycle, h_bounds=bounds, delta=self.delta, channels=tuple(gains))
        if not explicit:
            for i, c in enumerate(gains):
                if c.f > self.delta[i]:
                    raise InfeasibleDesign(
                        f"{what}, channel {i + 1}: eta = {c.eta:.6g} gives f = {c.f:.6g} > delta = {self.delta[i]:g} "
                        "with the verified kappa; increase the margin"
                    )
        return d

    def design(self, cycle: Cycle, *, eta: Sequence[float] | None = None) -> CycleDesign:
        """Gains for one cycle: eta_i = eta_min_i + margin (or ``eta`` given explicitly)."""
        self._check_cycle(cycle)
        what = f"cycle {cycle.label()}"
        if eta is None:
            emin: tuple[float | None, ...] = self.eta_min(cycle)
        else:  # explicit rates: eta_min is information only (None where no rate meets delta)
            emin = tuple(self._eta_min_or_none(cycle, i) for i in range(self.system.N))
        if eta is None:
            etas = [self.margin.apply(e) for e in emin]
        else:
            etas = [as_finite(e, f"eta_{i + 1}") for i, e in enumerate(eta)]
            if len(etas) != self.system.N or any(e <= 0 for e in etas):
                raise InvalidArgument(f"eta must give {self.system.N} positive rates; got {list(eta)}")
        gains = []
        for i in range(self.system.N):
            try:
                gains.append(self._channel_gain(i, etas[i], emin[i], cycle.active(i + 1), cycle.inactive(i + 1)))
            except DesignError as err:   # name the cycle and channel whose SDP failed
                raise type(err)(f"{what}, channel {i + 1}: {err}") from None
        return self._finish("cycle", cycle, None, gains, eta is not None, what)

    def design_robust(self, h_min: float, h_max: float) -> CycleDesign:
        """One gain set valid for every schedule with residence times in [h_min, h_max] (A2)."""
        h_min, h_max = as_finite(h_min, "h_min"), as_finite(h_max, "h_max")
        if not 0 < h_min <= h_max:
            raise ScheduleError(f"residence-time bounds need 0 < h_min <= h_max; got [{h_min}, {h_max}]")
        N = self.system.N
        what = f"robust design h in [{h_min:g}, {h_max:g}]"
        check_unseen(self.system, [(N - 1) * h_max] * N, power=1, what=f"the {what}")
        gains = []
        for i, ch in enumerate(self.channels):
            inactive = (N - 1) * (h_max if ch.mu >= 0 else h_min)
            emin = ch.eta_min(h_min, inactive, self.delta[i], what=f"{what}, channel {i + 1}: ")
            try:
                gains.append(self._channel_gain(i, self.margin.apply(emin), emin, h_min, inactive))
            except DesignError as err:
                raise type(err)(f"{what}, channel {i + 1}: {err}") from None
        return self._finish("robust", None, (h_min, h_max), gains, False, what)

    def table(
        self,
        cycles: Iterable[Cycle] = (),
        *,
        robust: tuple[float, float] | None = None,
        etas: Sequence[Sequence[float] | None] | None = None,
        progress: bool | None = None,
    ) -> GainTable:
        """Design every cycle (and the robust box) and collect them in a :class:`GainTable`."""
        cycles = list(cycles)
        for k, c in enumerate(cycles):
            if not isinstance(c, Cycle):
                raise InvalidArgument(f"cycles[{k}] must be a Cycle; got {c!r}")
        if robust is not None:
            try:
                hmin, hmax = (float(b) for b in robust)
            except (TypeError, ValueError):
                raise InvalidArgument(f"robust must be a pair (h_min, h_max); got {robust!r}") from None
            if not (math.isfinite(hmin) and math.isfinite(hmax) and 0 < hmin <= hmax):
                raise InvalidArgument(f"robust must be (h_min, h_max) with 0 < h_min <= h_max; got {robust!r}")
        uniq: list[tuple[Cycle, Sequence[float] | None]] = []
        for k, c in enumerate(cycles):
            e = etas[k] if etas is not None else None
            if not any(c.matches(u) for u, _ in uniq):
                uniq.append((c, e))
        jobs = len(uniq) + (1 if robust else 0)
        if jobs == 0:
            raise InvalidArgument("nothing to design: give at least one cycle in cycles or a robust box")
        bar = _progress(jobs, progress)
        designs = []
        try:
            for c, e in uniq:
                bar.set_description(f"design {c.label()}")
                designs.append(self.design(c, eta=e))
                bar.update(1)
            rob = None
            if robust is not None:
                bar.set_description("robust design")
                rob = self.design_robust(*robust)
                bar.update(1)
        finally:
            bar.close()
        return GainTable(
            system_name=self.system.name,
            fingerprint=self.system.fingerprint(),
            n=self.system.n,
            p=self.system.p,
            delta=self.delta,
            settings={
                "margin": self.margin.to_dict(),
                "solver": self.solver,
                "theta_slack": THETA_SLACK,
                "rank_rtol": self.system.rtol,
            },
            channels=[
                {
                    "r": ch.decomp.r,
                    "mu": ch.mu,
                    "T_o": ch.decomp.T_o.tolist(),
                    "kappa_curve": {"eta": ch.curve.points()[0].tolist(), "kappa": ch.curve.points()[1].tolist()},
                }
                for ch in self.channels
            ],
            designs=designs,
            robust=rob,
        )

    def eta_min_map(
        self, taus: Sequence[float], s_values: Sequence[float], *, progress: bool | None = None
    ) -> np.ndarray:
        """eta_min over a (tau, s) grid for two channels: array (len(taus), len(s), 2).

        Uses the interpolated kappa curve (``ChannelDesigner.eta_min_interp``): a map for the
        design-region figures, not a certificate.
        """
        if self.system.N != 2:
            raise InvalidArgument("the (tau, s) design-region map is defined for two channels")
        out = np.empty((len(taus), len(s_values), 2))
        bar = _progress(len(taus) * len(s_values), progress)
        try:
            for a, tau in enumerate(taus):
                for b, s in enumerate(s_values):
                    c = Cycle.from_ts(tau, s)
                    for i, ch in enumerate(self.channels):
                        out[a, b, i] = ch.eta_min_interp(c.h[i], c.inactive(i + 1), self.delta[i])
                    bar.update(1)
        finally:
            bar.close()
        return out


def design_cycle(
    system: LTISystem,
    cycle: Cycle,
    *,
    delta: float | Sequence[float] = 0.99,
    eta: Sequence[float] | None = None,
    margin: Margin | None = None,
) -> CycleDesign:
    """Design (or, with ``eta``, synthesize at given rates) the gains of one cycle."""
    return Designer(system, delta=delta, margin=margin).design(cycle, eta=eta)


def design_table(
    system: LTISystem,
    cycles: Iterable[Cycle] = (),
    *,
    robust: tuple[float, float] | None = None,
    delta: float | Sequence[float] = 0.99,
    margin: Margin | None = None,
    etas: Sequence[Sequence[float] | None] | None = None,
    progress: bool | None = None,
) -> GainTable:
    """Design a gain table for ``cycles`` and optionally a robust box ``(h_min, h_max)``."""
    return Designer(system, delta=delta, margin=margin).table(cycles, robust=robust, etas=etas, progress=progress)


def _deltas(delta: float | Sequence[float], N: int) -> tuple[float, ...]:
    vals = [delta] * N if np.ndim(delta) == 0 else list(delta)  # type: ignore[list-item]
    if len(vals) != N:
        raise InvalidArgument(f"delta must be one number or {N} numbers; got {len(vals)}")
    out = tuple(as_finite(v, "delta") for v in vals)
    for v in out:
        if not 0 < v < 1:
            raise InvalidArgument(f"delta must lie in (0, 1) (the paper's Theorem 2); got {v}")
    return out


def _progress(total: int, enabled: bool | None):
    """A tqdm bar on stderr (shown on a terminal by default, off in pipes)."""
    from tqdm import tqdm

    return tqdm(total=total, disable=(None if enabled is None else not enabled), leave=False, unit="design")
