"""Screening: the model against the data, before the observer takes a sample.

With the consistency test on (``consistency.check``: ``auto``, the default, whenever a bound is
published), every sample is tested against the bound
the estimator publishes (:class:`switchobs_core.runtime.consistency.InnovationTest`): a sample whose
innovation exceeds what the bound allows proves the model broken for it. When exactly one other
channel explains it, it is re-attributed to that channel (``reattributed``); else it is rejected
(``inconsistent``) and every bound is withdrawn, with the reason, until a window of data
re-certifies them (below) or a reset. A published
guarantee is never silently false.

Without a declared noise bound (``noise.max``) the published bound is the noise-free one: with
``consistency.check: auto`` the test watches it (``watch_only``): a sample it cannot explain
withdraws the bounds (the data are noisy, or the model is off) and is still used, as the noise it
may hold was never excluded; with ``always`` (noise-free samples asserted) or a declared
``noise.max`` (0: noise-free) such a sample is rejected.

With noise and no declared bound there is no guarantee to test against; the chi-square gate
(:class:`switchobs_core.runtime.gate.ChiSquareGate`, ``consistency.chi2_alpha``) then rejects samples
whose normalised innovation the noise model makes improbable (``outlier``).

The recovery of the guarantee (:class:`switchobs_core.runtime.recovery.Recovery`): a sample that
passes goes through the bias test (``consistency.bias``: an alarm withdraws the bounds); once the
observer took it, :meth:`Screening.taken` lets a window of data re-certify withdrawn bounds
(``consistency.recertify``); a channel whose samples the gate rejects ``STARVE`` times in a row is
a model failure of the body only it sees, re-initialised from its samples (``consistency.reinit``).

The math is the core's; this module decides what the pipeline does with the outcome.
"""

from __future__ import annotations

import numpy as np

from msg_bridge import Reason, Rejection
from switchobs_core.model.measurement import Measurement
from switchobs_core.runtime.consistency import Consistency, InnovationTest, consistent_channels, likely_causes
from switchobs_core.runtime.gate import ChiSquareGate
from switchobs_core.runtime.recovery import Recovery

from .counters import Counters
from .pairing import Pairing, Pending

__all__ = ["Screening", "same_outputs"]


def same_outputs(C_a, C_b) -> bool:
    """Whether two tuples of output matrices hold the same doubles, C-contiguous both (so ``C_r @ x`` gives
    the same doubles from either)."""
    return len(C_a) == len(C_b) and all(
        a.shape == b.shape and a.dtype == b.dtype == np.float64 and a.flags.c_contiguous and b.flags.c_contiguous
        and np.array_equal(a, b) for a, b in zip(C_a, C_b))


class Screening:
    """The consistency test (``check``) or the chi-square gate (``chi2_alpha > 0``) for the
    pipeline's samples.

    Parameters
    ----------
    system : System
        The system (its ``C_1..C_N``).
    observer : SwitchedObserver
        Gives the prior (:meth:`~switchobs_core.runtime.observer.SwitchedObserver.prior`) and the prior
        covariance of each test.
    pairing : Pairing
        Reads a sample as another channel's measurement.
    counters : Counters
        Where outcomes are counted, rejections recorded and bounds withdrawn (the pipeline).
    """

    def __init__(self, system, observer, pairing: Pairing, counters: Counters, *, check: bool, chi2_alpha: float):
        self.observer = observer
        self.pairing = pairing
        self.counters = counters
        self.N = system.N
        self.C = system.C
        self.check = bool(check)
        #: Test without rejecting: a sample the bound cannot explain withdraws the bounds and is used all the same
        #: (``consistency.check: auto`` without ``noise.max``: noise is then not excluded, only undeclared).
        self.watch_only = False
        self.innovation = InnovationTest(system.C, observer.noise_max)
        self.gate = ChiSquareGate(system.C, chi2_alpha)
        self.labels = getattr(system, "output_labels", None)
        self.recovery = Recovery(observer, labels=self.labels)
        #: The innovation test's ``C`` is the bias test's (the same doubles, contiguous): its innovation is shared.
        self.shared_innovation = same_outputs(self.innovation.C, observer.C)
        self._nu = None         # the innovation of the sample that passed the test last (admit)
        if observer.e0 is None:     # no initial error bound: no bound until the data certify one
            counters.bound_valid, counters.bound_invalid_why = False, observer.bounds_withdrawn

    def options(self, recertify: bool, bias: bool, reinit: bool) -> None:
        """Switch the recovery's parts (``consistency.recertify``, ``.bias``, ``.reinit``)."""
        self.recovery = Recovery(self.observer, recertify=bool(recertify), bias=bool(bias), reinit=bool(reinit),
                                 labels=self.labels)

    @property
    def chi2_alpha(self) -> float:
        """The chi-square gate's false-alarm rate (0: no gate)."""
        return self.gate.alpha

    @chi2_alpha.setter
    def chi2_alpha(self, alpha: float) -> None:
        self.gate = ChiSquareGate(self.C, alpha)

    @property
    def testing(self) -> bool:
        """Whether the consistency test runs now (on, and the bounds not withdrawn)."""
        return self.check and self.counters.bound_valid

    @property
    def names(self) -> bool:
        """Whether the test may name a sample's channel (re-attribution, samples sent in a loss of channel
        messages): it runs, and noise is excluded (declared, or noise-free samples asserted: not
        ``watch_only``, where a noisy sample could fit another channel's noise-free reading by chance)."""
        return self.testing and not self.watch_only

    def admit(self, pend: Pending, t: float, m: Measurement) -> Measurement | None:
        """The measurement to use at ``t`` (``m``, or another channel's reading of the sample), or
        None when the consistency test or the chi-square gate rejects the sample."""
        if not self.testing:
            if self.chi2_alpha > 0 and not self._gate(pend, t, m):
                self.counters.dropped[Reason.OUTLIER.value] += len(pend.parts)
                return None
            return self._bias(pend, t, m, None, None)
        with np.errstate(all="ignore"):     # the prior, both tests and the bias test's covariance: one error state
            prior = self.observer.prior(t, lazy=True)
            self._nu = None
            m = self._consistent(pend, t, m, prior)
            if m is None:
                self.counters.dropped[Reason.INCONSISTENT.value] += len(pend.parts)
                return m
            nu, self._nu = self._nu, None
            return self._bias(pend, t, m, prior[0], nu, quiet=True)

    def _bias(self, pend: Pending, t: float, m: Measurement, x_p, nu, quiet: bool = False) -> Measurement:
        """``m`` through the bias test (``x_p``: the held prediction at ``t`` and ``nu``: the innovation
        ``y - C_r x_p`` when the innovation test computed them, else None; ``quiet``: the caller holds
        ``np.errstate(all="ignore")``): an alarm withdraws the bounds, the sample is used."""
        why = self.recovery.before(t, m.channel, m.rows, m.y, x_p, nu, quiet=quiet)
        if why:         # the bias test: the sample is used, the bounds no longer hold
            ctr = self.counters
            ctr.bias_alarms += 1
            ctr.last_alarm = f"stamp {pend.stamp_ns}: {why}"
            if ctr.bound_valid:     # a withdrawal keeps its first reason
                ctr.withdraw(f"at stamp {pend.stamp_ns}: {why}")
        return m

    def taken(self, pend: Pending, t: float, m: Measurement) -> bool:
        """The observer took ``m`` at ``t``: while the bounds are withdrawn it joins the window, and
        a window that certifies a bound publishes the bounds again (labelled re-certified). True
        when it did: the estimate may then have restarted from the window's fit."""
        ctr = self.counters
        cert = self.recovery.after(t, m.channel, m.rows, m.y, ctr.bound_valid)
        if cert is not None:
            ctr.recertify(f"re-certified from data at stamp {pend.stamp_ns} (a window of "
                          f"{cert.t - cert.t_start:.3g} s, {cert.samples} samples; ||x - x_ls|| <= {cert.radius:.3g})")
        return cert is not None

    def fitting_channels(self, pend: Pending, t: float) -> list[int]:
        """The channels whose reading of the pending sample passes the innovation test at ``t``."""
        with np.errstate(all="ignore"):
            prior = self.observer.prior(t, lazy=True)
        return consistent_channels([self._test(prior, self.pairing.measurement(pend, c))
                                    for c in range(1, self.N + 1)])

    def _test(self, prior: tuple, m: Measurement) -> Consistency:
        return self.innovation.check(prior, m.channel, m.rows, m.y)

    def _consistent(self, pend: Pending, t: float, m: Measurement, prior: tuple) -> Measurement | None:
        """``m`` when it passes the innovation test against ``prior`` (the observer's at ``t``); the
        reading of the one other channel that passes when exactly one does (only a sample whose channel
        came from the channel topic can have another); else None: rejected, and the bounds withdrawn."""
        first = self._test(prior, m)
        if first.ok:
            if self.shared_innovation:
                self._nu = first.nu
            return m
        ctr = self.counters
        srcs = self.pairing.sources
        if not self.watch_only and any(srcs[i].channel is None and not srcs[i].shared for i in pend.parts):
            fits = [mc for mc in (self.pairing.measurement(pend, c) for c in range(1, self.N + 1) if c != m.channel)
                    if self._test(prior, mc).ok]
            if len(fits) == 1:
                ctr.reattributed += 1
                ctr.log.warn(f"sample at stamp {pend.stamp_ns} re-attributed from channel {m.channel} to "
                             f"{fits[0].channel}, the only channel consistent with it ({first.describe()})",
                             throttle=True)
                return fits[0]
        if self.watch_only:
            ctr.last_inconsistency = f"stamp {pend.stamp_ns}: {first.describe()}"
            ctr.withdraw(f"sample at stamp {pend.stamp_ns} beyond the noise-free exact_bound ({first.describe()}): "
                         "noisy samples while noise.max is not declared (declare it: 0 for noise-free sensors), or "
                         "the model does not hold for the data; the sample is used")
            return m
        ctr.inconsistent += 1
        ctr.last_inconsistency = f"stamp {pend.stamp_ns}: {first.describe()}"
        ctr.reject(self.pairing.topic(pend), Rejection(Reason.INCONSISTENT, "innovation", first.describe()))
        obs = self.observer         # the first sample (t = 0): its prior is x_hat(t0) with the ball of radius e0
        dist = None if obs.disturbance is None else float(max(obs.disturbance.w_max))
        why = likely_causes(t == 0.0, first.ratio, e0=obs.e0, noise_max=max(obs.noise_max or (0.0,)) if
                            obs.noise_max is not None else None, disturbance_max=dist)
        ctr.withdraw(f"inconsistent sample at stamp {pend.stamp_ns} ({first.describe()}): {why}")
        return None

    def _gate(self, pend: Pending, t: float, m: Measurement) -> bool:
        """The chi-square gate: False, counted and rejected, when the sample's normalised
        innovation exceeds it (no bound is involved: none is claimed under such noise)."""
        obs = self.observer
        with np.errstate(all="ignore"):
            P = obs.prior_covariance(t)
            if P is None or obs.noise is None:
                return True
            x_p = obs.predict(t, hold=True)
        g = self.gate.check(m.channel, m.rows, m.y, x_p, P, obs.noise.R(m.channel, m.rows))
        if g.ok:
            self.recovery.accepted(m.channel)
            return True
        ctr = self.counters
        ctr.outliers += 1
        ctr.reject(self.pairing.topic(pend), Rejection(Reason.OUTLIER, "innovation", g.describe()))
        why = self.recovery.rejected(t, m.channel, m.rows, m.y)
        if why:         # not outliers: the body does not move as the model says
            ctr.model_failures += 1
            ctr.last_alarm = f"stamp {pend.stamp_ns}: {why}"
            if ctr.bound_valid:
                ctr.withdraw(f"at stamp {pend.stamp_ns}: {why}")
        return False
