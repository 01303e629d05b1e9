"""Runs of the observer on a plant driven by an unknown bounded input (manoeuvring bodies).

The plant ``xdot = A x + B_w w`` (:class:`~switchobs_core.sim.plant.Plant` with ``B_w``, in
extended precision: the error column is the computed estimate's true error), sampled at ``rate``
Hz on the schedule's channel with noise clipped to ``+-noise_max``, goes through
:class:`~switchobs_core.runtime.observer.SwitchedObserver` with the innovation consistency test of
:mod:`switchobs_core.runtime.consistency` before every sample, as the node runs it: the first
inconsistent sample withdraws the bounds (nothing is published as valid after it). The signals:
:func:`bang_bang` (every input at a corner of its box, signs switching at random) and
:func:`step_input` (one input from a time on: a body that starts to accelerate).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..runtime.consistency import InnovationTest
from ..runtime.observer import SwitchedObserver
from .plant import Plant

__all__ = ["DisturbedRun", "bang_bang", "disturbed_run", "step_input"]


def bang_bang(w_max: Sequence[float], rate: float, seed: int = 0,
             mean_hold: float = 0.5) -> Callable[[float], np.ndarray]:
    """``w(t)``: each input at ``+-w_max_j``, its sign drawn again at every sample with probability
    ``1 / (mean_hold rate)`` (a switch every ``mean_hold`` seconds on average); seeded."""
    m = np.asarray(w_max, dtype=float)
    rng = np.random.default_rng(seed)
    sign = rng.choice((-1.0, 1.0), m.size)
    flip = 1.0 / max(mean_hold * rate, 1.0)
    state = {"k": -1}

    def w(t: float) -> np.ndarray:
        k = round(t * rate)
        while state["k"] < k:
            state["k"] += 1
            sign[rng.random(m.size) < flip] *= -1.0
        return sign * m
    return w


def step_input(q: int, j: int, value: float, t_on: float) -> Callable[[float], np.ndarray]:
    """``w(t) = value e_j`` from ``t_on`` on, 0 before (0-based ``j``)."""
    def w(t: float) -> np.ndarray:
        out = np.zeros(q)
        if t >= t_on:
            out[j] = value
        return out
    return w


@dataclass
class DisturbedRun:
    """Per sample: time, true error ``||x_hat - x||``, published ``noise_bound`` (``inf`` once
    withdrawn); the time of the withdrawal (``nan``: none) and its reason."""

    t: np.ndarray
    error: np.ndarray
    bound: np.ndarray
    withdrawn_at: float
    reason: str

    def false_samples(self) -> int:
        """Samples published with a valid bound below the true error."""
        return int(np.sum(np.isfinite(self.bound) & (self.error > self.bound)))

    def valid_fraction(self, after: float) -> float:
        """Fraction of the samples from ``after`` on with a valid (finite) bound."""
        sel = self.t >= after
        return float(np.mean(np.isfinite(self.bound[sel]))) if np.any(sel) else math.nan

    def median_ratio(self, after: float) -> float:
        """Median of ``bound / error`` over the samples from ``after`` on with a valid bound."""
        sel = (self.t >= after) & np.isfinite(self.bound) & (self.error > 0)
        return float(np.median(self.bound[sel] / self.error[sel])) if np.any(sel) else math.nan


def disturbed_run(system: Any, observer: SwitchedObserver, schedule: Any, rate: float, seconds: float,
                  x0: Any, B_w: np.ndarray, w: Callable[[float], np.ndarray], *, noise_std: float = 0.0,
                  noise_max: float = 0.0, seed: int = 0) -> DisturbedRun:
    """Run ``observer`` (declared ``noise_max``, and its disturbance or none) on the plant from
    ``x0`` driven by ``w`` through ``B_w`` (module docstring); ``schedule`` has ``channel_at(t)``."""
    plant = Plant(system, x0, seed=seed, extended=True, B_w=B_w)
    test = InnovationTest(system.C, observer.noise_max)
    rng = np.random.default_rng(seed + 1)
    ts, errs, bounds = [], [], []
    withdrawn_at, reason = math.nan, ""
    t0 = observer.t
    for k in range(round(seconds * rate) + 1):
        t = t0 + k / rate
        if k:
            plant.advance(t, w=w(t - 1.0 / rate))     # w held over the step, from its start
        rho = int(schedule.channel_at(t - t0))
        y = plant.measure(rho)
        if noise_std > 0:
            y = y + np.clip(noise_std * rng.standard_normal(y.shape), -noise_max, noise_max)
        if math.isnan(withdrawn_at):
            c = test.check(observer.prior(t), rho, None, y)
            if not c.ok:
                withdrawn_at, reason = t, c.describe()
        observer.update(t, rho, y)
        env = observer.envelope()
        ts.append(t)
        errs.append(float(np.linalg.norm(np.asarray(plant.x_extended - observer.x_hat, dtype=float))))
        bounds.append(env.noise_bound if math.isnan(withdrawn_at) else math.inf)
    return DisturbedRun(np.array(ts), np.array(errs), np.array(bounds), withdrawn_at, reason)
