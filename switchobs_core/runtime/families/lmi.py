"""The paper's gain family: LMI gains per cycle, the innovation (or measurement) held (Section 4).

At a sample on channel ``i`` the gain ``L_i`` of the current design (per cycle, e:L_original)
is selected and the innovation ``nu = y - C_i x_hat`` (``hold="innovation"``) or the sample
(``hold="measurement"``) is held until the next sample; the observer's next exact step applies
it (e:switched_observer). A sample inside a design's dead time gets no gain. The family
returns the held innovation (:class:`~switchobs_core.runtime.families.base.Held`: the gain's ZOH
key, ``nu``, the rows and the data) and changes no estimate at the sample. With a noise model it
keeps the covariance, propagated through the exact error map of each step with the held noise
driven through ``Gamma L`` (:mod:`switchobs_core.runtime.covariance`), when it is read: the steps
wait until then (:class:`~switchobs_core.runtime.covariance.PendingSteps`, O(1) per sample; a run of
equal steps by binary powers), so a sample costs no n x n product where no output reads ``P``. The
prior a consistency test reads at a sample (:meth:`LmiGains.predict_covariance`) is the step the
sample's update then takes, by the same arithmetic from the same covariance: it is kept and becomes the
covariance (one propagation per sample where the test and an output both read it, the same numbers).
A bias test reads the prior's block on a sample's columns only (:meth:`LmiGains.stored_prior`): from the
block of ``P`` the held step maps into itself, carried step by step
(:class:`~switchobs_core.runtime.covariance.HeldBlock`), so the full steps still wait; where ``P`` is read
at every sample (a publisher), the block of the full prior, which the family computes from the covariance
it keeps and keeps for the step (the same doubles as the prior of a copy of ``P``, without the copy).
"""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np

from ...exceptions import InvalidArgument
from ...model.noise import default_noise
from ..covariance import CovarianceStep, HeldBlock, HeldNoise, PendingSteps
from .base import OPEN_LOOP, Correction, FamilyContext, Held, Sample, check_bounds, check_cycles

__all__ = ["LmiGains"]


class LmiGains:
    """The ``lmi`` family (module docstring): a :class:`~switchobs_core.runtime.families.base.GainFamily`.

    ``LmiGains(ctx, table, mode, cycles, bounds=None, noise=None, track_covariance=None)``
    """

    name: ClassVar[str] = "lmi"
    paper_envelope: ClassVar[bool] = True
    holds: ClassVar[tuple[str, ...]] = ("innovation", "measurement")
    kalman = None

    def __init__(self, ctx: FamilyContext, table: Any, mode: str, cycles: Any, *, bounds: Any = None,
                 noise: Any = None, track_covariance: bool | None = None, **_: Any) -> None:
        if getattr(table, "family", "lmi") != "lmi":
            raise InvalidArgument(f"family 'lmi' needs an LMI gain table; this table holds {table.family!r} gains")
        self._ctx = ctx
        # 1. designs of the mode
        if mode == "robust":
            d = getattr(table, "robust", None)
            if d is None:
                raise InvalidArgument("table has no robust design (table.robust is None); "
                                      "design one with design_table(..., robust=(h_min, h_max))")
            self.designs = (d,)
            self.promised = (None,)
            self.bounds = check_bounds(getattr(d, "h_bounds", None) if bounds is None else bounds)
        else:
            cycles = check_cycles(cycles, mode, ctx.N)
            self.designs = tuple(table.lookup(c) for c in cycles)
            self.promised = tuple(cycles)
            self.bounds = None
        for d in self.designs:
            for i, Li in enumerate(d.L):
                if np.shape(Li) != (ctx.n, ctx.p[i]):
                    raise InvalidArgument(f"design gain L_{i + 1} has shape {np.shape(Li)}; "
                                          f"expected {(ctx.n, ctx.p[i])}")
        self._L = tuple(tuple(np.ascontiguousarray(Li, dtype=float) for Li in d.L) for d in self.designs)
        # 2. covariance: propagated under the noise model when one is given (or asked for)
        if track_covariance is None:
            track_covariance = noise is not None
        if track_covariance and noise is None:
            noise = default_noise(ctx.system)
        if track_covariance and ctx.hold != "innovation":
            raise InvalidArgument("track_covariance needs hold='innovation' (the exact error map)")
        self.noise = noise
        self.track_covariance = bool(track_covariance)
        if noise is not None:
            noise.check_system(ctx.system)
            self._cov = CovarianceStep(ctx.A, ctx.B, noise, ctx.dt_resolution)
            self._pending = PendingSteps(self._cov)
            self._block = HeldBlock(self._cov)
        self._keys: dict = {}       # (design, channel, rows) -> (ZOH key, C rows)
        self._Rs: dict = {}         # (channel, rows) -> R of those rows
        self._P: np.ndarray | None = None
        self._prior: tuple | None = None    # (P, e, Q_d, R, P through e): the last prior (predict_covariance)
        self._noises = HeldNoise()
        self._held: Held | None = None
        self._R_held = None
        self._read = False      # P read since the last step (a reader at every sample)

    @classmethod
    def design_table(cls, system: Any, cycles: Any, *, robust: Any = None, delta: float = 0.99, **_: Any) -> Any:
        """The paper's design (:func:`~switchobs_core.design.lmi.design_table`; the SDP stack imported here,
        by the start that designs, not by one that loads a table)."""
        from ...design.lmi import design_table
        return design_table(system, cycles=cycles, robust=robust, delta=delta)

    # ------------------------------------------------------------------ protocol
    @property
    def source(self) -> str:
        return "table"

    @property
    def held(self) -> Held | None:
        return self._held

    def reset(self) -> None:
        self._P = self.noise.P0.copy() if self.track_covariance else None
        if self.track_covariance:
            self._pending.clear()
            self._block.clear()
        self._prior = None
        self._held = None
        self._R_held = None
        self._read = False

    def fuses(self, input_held: bool) -> bool:
        return False

    def stepped(self, e: Any, dt: float) -> None:
        if self._P is not None:
            held = self._R_held if self._held is not None else None
            self._read = False
            self._block.step(e, dt, held)
            prior, self._prior = self._prior, None
            if (prior is not None and prior[0] is self._P and prior[1] is e and prior[2] is self._cov.q_d(dt)
                    and prior[3] is held and not len(self._pending) and self._cov.prior_is_step(e)):
                self._P = prior[4]      # the prior of this step, computed as the step computes it
                return
            if self._pending.push(e, dt, held):
                self._P = self._pending.apply(self._P)

    def covariance(self) -> np.ndarray | None:
        if self._P is None:
            return None
        if len(self._pending):
            self._P = self._pending.apply(self._P)
        self._read = True
        return self._P.copy()

    def stored_prior(self, t: float, dt: float, cols: np.ndarray | None = None) -> np.ndarray | None:
        """With ``cols`` (a bias test's block): the prior's block on them from the block of ``P`` the
        step maps into itself (:class:`~switchobs_core.runtime.covariance.HeldBlock`, started from the
        full covariance when it is not the one kept), without the n x n prior; where ``P`` was read since
        the last step (a reader at every sample: the full prior is then the step the sample takes, and
        the block would be work added), the block of the full prior, computed from the covariance kept
        and kept for the step (:meth:`predict_covariance`'s arithmetic on the same doubles, those of a
        reader's copy, in C order, without a copy of ``P`` to compare and a copy of the prior to
        keep); else None."""
        if cols is None or self._P is None:
            return None
        h = self._held
        e = self._ctx.zoh(OPEN_LOOP if h is None else h.key, dt)
        if self._read and not len(self._pending):
            self._block.clear()
            # C order: the doubles of the reader's copy of P (the products' rounding depends on the layout)
            self._P = np.ascontiguousarray(self._P)
            prior = self._cov.prior(self._P, e, dt, self._held_noise(e))
            self._prior = (self._P, e, self._cov.q_d(dt), self._R_held if h is not None else None, prior)
            ix = np.asarray(cols)
            return prior[np.ix_(ix, ix)]
        got = self._block.closure(e, np.asarray(cols))
        if got is None:
            return None
        K, ix = got
        if not self._block.holds(K):
            if len(self._pending):
                self._P = self._pending.apply(self._P)
            self._block.start(self._P, K)
        B = self._block.prior(e, dt, self._R_held if h is not None else None)
        return B[ix]

    def predict_covariance(self, P: np.ndarray, e: Any, dt: float) -> np.ndarray:
        """The prior through ``e``; kept (a copy) for :meth:`stepped` when ``P`` is the covariance kept."""
        prior = self._cov.prior(P, e, dt, self._held_noise(e))
        if self._P is not None and not len(self._pending) and np.array_equal(P, self._P):
            held = self._R_held if self._held is not None else None
            self._prior = (self._P, e, self._cov.q_d(dt), held, prior.copy())
        return prior

    def depart(self, why: str) -> None:
        return None

    def set_covariance(self, P: np.ndarray) -> None:
        if self._P is not None:
            self._pending.clear()
            self._block.clear()
        self._prior = None
        self._P = P

    def _held_noise(self, e: Any) -> np.ndarray | None:
        """``(Gamma L) R (Gamma L)'``: the held sample's noise over the step (innovation hold), kept
        per step and ``R``."""
        if self._held is None or self._R_held is None:
            return None
        return self._noises(e, self._R_held)

    def _gain_key(self, design: int, channel: int, rows: Any) -> tuple:
        """ZOH cache key and output rows of channel ``channel`` with rows ``rows`` under design
        ``design`` (registered in the observer's cache at first use)."""
        ck = (design, channel, rows)
        hit = self._keys.get(ck)
        if hit is not None:
            return hit
        ctx = self._ctx
        Ci = ctx.C[channel - 1]
        Li = self._L[design][channel - 1]
        if rows is not None:
            Ci = Ci[list(rows), :]
            Li = Li[:, list(rows)]
        if ctx.hold == "innovation":
            ctx.register(ck, ctx.A, Li, ctx.B, C=Ci)
        else:
            ctx.register(ck, ctx.A - Li @ Ci, Li, ctx.B)
        hit = self._keys[ck] = (ck, Ci)
        return hit

    def sample(self, s: Sample) -> Correction:
        """Hold the sample's innovation (or the sample) with the gain of the current design."""
        rows, y = s.rows, s.y
        if s.blind:     # dead time after the switch: no gain (module docstring)
            rows, y = (), y[:0]
        key, Cr = self._gain_key(s.design, s.channel, rows)
        x = s.x
        self._held = held = Held(key, y - Cr @ x if self._ctx.hold == "innovation" else y, Cr, y)
        if self._P is not None:     # one array per (channel, rows): equal steps are seen as equal
            rk = (s.channel, None if rows is None else tuple(rows))
            R = self._Rs.get(rk)
            if R is None:
                R = self._Rs[rk] = self.noise.R(s.channel, rows)
            self._R_held = R
        return Correction(x, (), held)
