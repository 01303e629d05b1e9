"""Switching instants, residence times and cycles of one observer run (e:switching_instants).

A *cycle* runs from one channel-1 start to the next (e:tau_k); channel i is active for a
*residence time* ``h_i`` in it. :class:`CycleTracker` is the single owner of this
bookkeeping: the switching instants, the active channel's residence so far, the residence
interval the gains in use were designed for (the scheduled ``h_i +- match_tol``, or A2's box
``[h_min - match_tol, h_max + match_tol]`` in robust mode), each completed cycle as a
:class:`CycleRecord`, the count of residences outside their interval and the one-line
statement of the latest one. :class:`~switchobs_core.runtime.observer.SwitchedObserver` drives it; the
ROS pipeline only reports :meth:`CycleTracker.residence`.

Equation labels (``e:...``) are those of the paper and resolve in ``docs/equations.md``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..certificate.paper import paper_factors
from ..exceptions import SwitchobsError

__all__ = ["CycleRecord", "Residence", "CycleTracker", "residence_limits", "residence_text"]


@dataclass(frozen=True)
class CycleRecord:
    """One completed switching cycle, as measured by the observer.

    Attributes
    ----------
    k : int
        Cycle index (0 for the cycle that starts at the first channel-1 start).
    t_start, t_end : float
        The two channel-1 starts that bound the cycle (``t_{2k}``, ``t_{2k+2}``).
    tau : float
        Measured length ``tau_k = t_end - t_start`` (e:tau_k).
    h : tuple of float
        Measured active time of each channel in the cycle (``h_1 = s_k tau_k``).
    s : float
        Measured duty fraction ``s_k = h_1 / tau_k`` (e:s_k).
    f : tuple of float
        The paper's factors ``f_ii = kappa_i exp(mu_i (tau - h_i) - eta_i h_i)`` for the
        measured durations and the gains used (e:f11_le_delta_main, e:f22_le_delta_main).
        The paper claims contraction when all are < 1; that claim is not a
        proof (see :mod:`switchobs_core.certificate`).
    order : tuple of int
        Channels in the order they were active during the cycle.
    promised : Any
        The scheduled :class:`~switchobs_core.model.schedule.Cycle` (None in robust mode).
    matched : bool
        Order was 1..N and every ``|h_i - promised.h_i| <= match_tol`` (robust mode:
        order 1..N and A2 held).
    a2_ok : bool or None
        Robust mode: every ``h_i`` within ``[h_min - match_tol, h_max + match_tol]``;
        None when no box is known.
    design_index : int
        Which entry of the mode's design list was used.
    """

    k: int
    t_start: float
    t_end: float
    tau: float
    h: tuple
    s: float
    f: tuple
    order: tuple
    promised: Any
    matched: bool
    a2_ok: bool | None
    design_index: int


@dataclass(frozen=True)
class Residence:
    """The active channel's residence time against what the gains were designed for.

    ``kind`` is ``"A2"`` (robust mode: ``[lo, hi] = [h_min, h_max]`` widened by
    ``match_tol``) or ``"schedule"`` (``h_i +- match_tol`` of the scheduled cycle).
    ``current`` is the active channel's time so far (s, from sample stamps); ``last`` the
    last completed residence ``(channel, h, lo, hi)``; ``f`` the paper's factors of the
    cycle so far (measured h; None before the first switch); ``violations`` the number of
    residences outside their interval since construction (kept through resets);
    ``problem`` a one-line statement when the assumption is broken now, else "".
    """

    kind: str
    channel: int
    current: float
    lo: float
    hi: float
    last: tuple | None
    f: tuple | None
    violations: int
    problem: str


def residence_limits(robust: bool, bounds: tuple[float, float] | None, match_tol: float,
                     h: float | None) -> tuple[float, float]:
    """The residence interval ``[lo, hi]`` (s) one channel was designed for.

    Robust mode: A2's box ``[max(h_min - match_tol, 0), h_max + match_tol]`` (``[0, inf)``
    when no box is known); otherwise the scheduled ``[max(h - match_tol, 0), h + match_tol]``.
    """
    if robust:
        if not bounds:
            return (0.0, math.inf)
        return (max(float(bounds[0]) - match_tol, 0.0), float(bounds[1]) + match_tol)
    return (max(h - match_tol, 0.0), h + match_tol)


def residence_text(robust: bool, match_tol: float, channel: int, h: float, lo: float, hi: float, *,
                   done: bool) -> str:
    """One line stating that channel ``channel``'s residence ``h`` left ``[lo, hi]``.

    ``done``: the residence is over ("was active") rather than still running ("active").
    """
    what = "A2" if robust else "schedule"
    tol = match_tol
    if robust:
        bound = f"h_max {hi - tol:g} s" if h > hi else f"h_min {lo + tol:g} s"
    else:
        bound = f"the scheduled {(hi + lo) / 2:g} s"
    bound += f" (tolerance {tol:g} s)"
    verb = "was active" if done else "active"
    rel = ">" if h > hi else "<"
    return f"{what} broken: channel {channel} {verb} {h:.3f} s {rel} {bound}"


class CycleTracker:
    """Residence and cycle bookkeeping of one observer (e:switching_instants, e:tau_k).

    Parameters
    ----------
    N : int
        Number of output channels.
    mode : str
        The observer's mode; ``"robust"`` judges residences against A2's box, any other
        against the scheduled cycle.
    bounds : (float, float) or None
        ``(h_min, h_max)`` of A2 (robust mode).
    match_tol : float
        Tolerance (s) on every measured residence time.
    t0 : float
        Start time.

    Notes
    -----
    The first residence after start-up or a reset began before the first sample: its
    measured time is only a lower bound, so it is not judged against the lower limit.
    ``violations`` survives :meth:`reset`.
    """

    def __init__(self, N: int, mode: str, bounds: tuple[float, float] | None, match_tol: float,
                 t0: float = 0.0):
        self.N = N
        self.robust = mode == "robust"
        self.bounds = bounds
        self.match_tol = match_tol
        self.violations = 0
        self.reset(t0)

    def reset(self, t0: float) -> None:
        """Forget the switching history (keeps ``violations``)."""
        self.channel = 0
        self.since = t0
        self.limits = (0.0, math.inf)
        self.h = np.zeros(self.N)
        self.order: list[int] = []
        self.cycle_start: float | None = None
        self.last: tuple | None = None
        self.started = False
        self.problem_at_switch = ""

    def limits_for(self, design: Any, channel: int) -> tuple[float, float]:
        """Designed residence interval of ``channel`` (1-based) under ``design``."""
        h = None if self.robust else design.cycle.h[channel - 1]
        return residence_limits(self.robust, self.bounds, self.match_tol, h)

    def text(self, channel: int, h: float, lo: float, hi: float, *, done: bool) -> str:
        """:func:`residence_text` with this tracker's mode and tolerance."""
        return residence_text(self.robust, self.match_tol, channel, h, lo, hi, done=done)

    def end_residence(self, t: float) -> tuple | None:
        """Close the active channel's residence at the switching instant ``t``.

        Judges it against its interval (counting a violation and stating it in
        ``problem_at_switch``) and adds it to the open cycle's ``h``. Returns ``last``:
        ``(channel, h, lo, hi, judged)``, or None when no channel was active.
        """
        self.problem_at_switch = ""
        old = self.channel
        if not old:
            return None
        h = t - self.since
        lo, hi = self.limits
        if h > hi or (h < lo and self.started):
            self.violations += 1
            self.problem_at_switch = self.text(old, h, lo, hi, done=True)
        self.h[old - 1] += h
        self.last = (old, h, lo, hi, self.started)
        self.started = True
        return self.last

    def cycle_so_far(self, t: float) -> tuple[float, tuple[float, ...], tuple[int, ...]]:
        """``(tau, h, order)`` of the open cycle at a channel-1 start ``t``."""
        return t - self.cycle_start, tuple(float(v) for v in self.h), tuple(self.order)

    def begin(self, t: float, channel: int, limits: tuple[float, float]) -> None:
        """Start ``channel``'s residence at ``t`` with the designed interval ``limits``;
        a channel-1 start also starts a new cycle."""
        if channel == 1:
            self.cycle_start = t
            self.h[:] = 0.0
            self.order = []
        self.order.append(channel)
        self.channel = channel
        self.since = t
        self.limits = limits

    def close_cycle(self, t: float, k: int, design: Any, design_index: int, promised: Any,
                    sequence: bool) -> tuple[CycleRecord, bool]:
        """The :class:`CycleRecord` of the cycle that ends at the channel-1 start ``t``.

        Returns the record and whether the observer should re-sync its sequence (sequence
        mode, order 1..N, durations not those promised).
        """
        tau, h, order = self.cycle_so_far(t)
        order_ok = order == tuple(range(1, self.N + 1))
        tol = self.match_tol
        a2_ok = None
        resync = False
        if self.robust:
            if self.bounds is not None:
                lo, hi_ = residence_limits(True, self.bounds, tol, None)
                a2_ok = all(lo <= hi <= hi_ for hi in h)
            matched = order_ok and a2_ok is not False
        else:
            matched = order_ok and self.matches(h, promised)
            resync = not matched and order_ok and sequence
        f = () if design.kappa is None else paper_factors(design, h)    # Kalman gains: no paper factors
        rec = CycleRecord(k=k, t_start=self.cycle_start, t_end=t, tau=tau, h=h,
                          s=h[0] / tau if tau > 0 else float("nan"), f=f, order=order, promised=promised,
                          matched=bool(matched), a2_ok=a2_ok, design_index=design_index)
        return rec, resync

    def matches(self, h: tuple, cycle: Any) -> bool:
        """Every measured ``h_i`` within ``match_tol`` of ``cycle.h``."""
        return all(abs(hi - ph) <= self.match_tol for hi, ph in zip(h, cycle.h))

    def residence(self, t: float, design: Any) -> Residence | None:
        """The active channel's residence at time ``t`` against the design (None before the
        first sample); ``design`` (the gains in use) gives the paper's factors of the cycle so far."""
        c = self.channel
        if not c:
            return None
        cur = t - self.since
        lo, hi = self.limits
        problem = ""
        if cur > hi:
            problem = self.text(c, cur, lo, hi, done=False)
        elif self.last is not None:
            lc, lh, llo, lhi, judged = self.last
            if lh > lhi or (lh < llo and judged):
                problem = self.text(lc, lh, llo, lhi, done=True)
        f = None
        if self.started and design.kappa is not None:
            h = self.h.copy()
            h[c - 1] += cur
            try:
                f = paper_factors(design, tuple(h))
            except SwitchobsError:
                f = None
        return Residence(kind="A2" if self.robust else "schedule", channel=c, current=cur, lo=lo, hi=hi,
                         last=None if self.last is None else self.last[:4], f=f,
                         violations=self.violations, problem=problem)
