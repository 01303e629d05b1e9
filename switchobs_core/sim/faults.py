"""A sampled run with sensor faults, the consistency test and the recovery of the guarantee.

:func:`run_with_faults` drives the run-time observer as the estimator does
(:mod:`switchobs_ros.screening`): each sample is tested against the published bound
(:class:`~switchobs_core.runtime.consistency.InnovationTest`); a sample that fails it is rejected
and every bound is withdrawn; the recovery of :mod:`switchobs_core.runtime.recovery` runs its bias
test before each sample and re-certifies the bounds from data afterwards. The plant is exact
(:class:`~switchobs_core.sim.plant.Plant`), its noise Gaussian clipped to ``noise_max``; a
:class:`Fault` adds an offset to some output rows over ``[t0, t1)`` (a biased or faulty sensor:
beyond the declared bound, so the guarantee does not cover it). The result holds, per sample,
the error, the published ``noise_bound`` (-1 while withdrawn) and the events.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..runtime.consistency import InnovationTest
from ..runtime.observer import SwitchedObserver
from ..runtime.recovery import Recovery
from .plant import Plant

__all__ = ["Fault", "FaultRun", "run_with_faults"]


@dataclass(frozen=True)
class Fault:
    """``offset`` added to the output rows ``rows`` (0-based, of every channel in ``channels``;
    None: all channels) of every sample in ``[t0, t1)``."""

    t0: float
    t1: float
    rows: tuple[int, ...]
    offset: float
    channels: tuple[int, ...] | None = None

    def applies(self, t: float, channel: int) -> bool:
        return self.t0 <= t < self.t1 and (self.channels is None or channel in self.channels)


@dataclass
class FaultRun:
    """Per sample: ``t``, ``error`` (``||x_hat - x||``), ``bound`` (the published noise bound, -1
    while withdrawn), ``used`` (the observer took the sample); ``withdrawals`` ``(t, why)``,
    ``recertified`` ``(t, Certificate)``, ``alarms`` ``(t, text)``."""

    t: np.ndarray
    error: np.ndarray
    bound: np.ndarray
    used: np.ndarray
    withdrawals: list = field(default_factory=list)
    recertified: list = field(default_factory=list)
    alarms: list = field(default_factory=list)

    @property
    def valid(self) -> np.ndarray:
        """Samples with a published bound."""
        return self.bound >= 0

    @property
    def false(self) -> int:
        """Samples whose published bound is below the error."""
        return int(np.sum(self.valid & (self.error > self.bound)))

    def valid_fraction(self, after: float) -> float:
        """The fraction of the samples from ``after`` on with a published bound."""
        sel = self.t >= after
        return float(np.mean(self.valid[sel])) if sel.any() else math.nan

    def first_bound_after(self, after: float) -> float:
        """The time from ``after`` to the first published bound at or after it (``inf``: none)."""
        sel = (self.t >= after) & self.valid
        return float(self.t[sel][0] - after) if sel.any() else math.inf


def run_with_faults(system: Any, table: Any, schedule: Any, x0: Any, xhat0: Any, t_end: float, *, rate: float,
                    noise_std: float, noise_max: float, e0: float | None = None, faults: Sequence[Fault] = (),
                    seed: int = 0, recovery: dict | None = None, noise: Any = None, B_w: Any = None,
                    w: Any = None, disturbance: Any = None) -> FaultRun:
    """Run the observer with the consistency test and :class:`~switchobs_core.runtime.recovery.Recovery`
    (options ``recovery``) on the plant from ``x0`` at ``rate`` Hz with Gaussian noise of ``noise_std``
    clipped to ``noise_max`` plus the ``faults``; ``e0`` None: no initial bound (certified from data).
    ``B_w``, ``w``: an unknown input ``w(t)`` (held over each step from its start) through ``B_w``
    drives the plant (a manoeuvre: :mod:`switchobs_core.sim.disturbed`); ``disturbance`` the
    observer's declared one (None: undeclared)."""
    cycles = list(schedule.cycles)
    obs = SwitchedObserver(system, table, "periodic", cycles, x0=xhat0, t0=0.0, e0=e0, noise_max=noise_max,
                           noise=noise, disturbance=disturbance)
    rec = Recovery(obs, labels=getattr(system, "output_labels", None), **(recovery or {}))
    test = InnovationTest(system.C, obs.noise_max)
    plant = Plant(system, x0, seed=seed, B_w=B_w)
    K = int(math.floor(t_end * rate + 1e-9))
    t = np.arange(K + 1) / rate
    err, bound, used = np.empty(K + 1), np.full(K + 1, -1.0), np.zeros(K + 1, dtype=bool)
    run = FaultRun(t, err, bound, used)
    valid = e0 is not None
    for k, tk in enumerate(t):
        x = plant.advance(float(tk), w=None if w is None or not k else w(float(t[k - 1])))
        c = schedule.channel_at(float(tk))
        y = plant.measure(c, noise_std, noise_max=noise_max)
        for f in faults:
            if f.applies(float(tk), c):
                y[list(f.rows)] += f.offset
        with np.errstate(all="ignore"):
            ok = True
            if valid:
                ok = test.check(obs.prior(float(tk)), c, None, y).ok
                if not ok:
                    valid = False
                    rec.withdrawn()
                    run.withdrawals.append((float(tk), "inconsistent sample"))
            if ok:
                why = rec.before(float(tk), c, None, y)
                if why:
                    run.alarms.append((float(tk), why))
                    if valid:
                        valid = False
                        run.withdrawals.append((float(tk), why))
                obs.update(float(tk), c, y)
                used[k] = True
                cert = rec.after(float(tk), c, None, y, valid)
                if cert is not None:
                    valid = True
                    run.recertified.append((float(tk), cert))
        env = obs.envelope()
        nb = env.noise_bound
        if valid and nb is not None and math.isfinite(nb):
            bound[k] = nb
        elif valid:         # a bound that can no longer be computed
            valid = False
            rec.withdrawn()
            run.withdrawals.append((float(tk), obs.bounds_withdrawn or "bound not finite"))
        err[k] = float(np.linalg.norm(obs.x_hat - x))
    return run
