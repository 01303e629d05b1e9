"""The arrays of one simulation (:func:`switchobs_core.sim.simulate.simulate`) and the bound they can call
guaranteed.

Paper labels (``e:...``, ``t:...``) resolve to numbers in ``docs/equations.md``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..families import family_entry

__all__ = ["SimulationResult"]


def paper_gains(family: str) -> bool:
    """Whether the paper's envelopes apply to a family's gains (the registry's type says)."""
    return bool(family_entry(family).type().paper_envelope)


@dataclass
class SimulationResult:
    """Arrays of one simulation (times along axis 0 unless said otherwise).

    Attributes
    ----------
    t : (T,) ndarray
    x, x_hat, error : (T, n) ndarray
        Plant state, estimate and ``x_tilde = x_hat - x`` (e:est_error).
    channel : (T,) ndarray of int
        Channel whose gain acts from ``t`` on (1-based).
    z : (N, T) ndarray
        The paper's envelopes (e:z1_evolution, e:z2_evolution), ``z_i(0^-) = e0``.
    paper_bound : (T,) ndarray
        ``alpha sum z_i``: the paper's claim (not a guarantee).
    exact_bound : (T,) ndarray
        ``||Phi(t, t0)|| e0`` with the rounding of the computation included (ours; see
        :mod:`switchobs_core.numerics.rounding`): a guarantee on :attr:`error` for noise-free continuous
        outputs and for noise-free sampled outputs with innovation hold (the default) or Kalman
        gains. With noise it is the *noise-free* bound, not a guarantee (:attr:`noisy`); with
        measurement hold it is the exact-arithmetic error-to-error part, see :attr:`hold_bound`.
    noise_bound : (T,) ndarray or None
        With a declared ``noise_max``: the observer's bound under any noise within it (ours).
    noisy : bool
        Measurement or process noise was drawn.
    hold_bound : (T,) ndarray or None
        Measurement hold only: ``||Phi_ee|| e0 + ||Phi_ex|| ||x(0)||`` with the blocks of
        :func:`~switchobs_core.sim.simulate.sampled_error_transition` along the run, a guarantee for
        noiseless samples with ``u = 0`` (exact arithmetic).
    xo_norms : (N, T) ndarray
        ``||x_tilde_o^(i)(t)|| = ||T_io' x_tilde(t)||`` (e:xtilde_decomp).
    switching_times : ndarray
        Switching instants used (for sampled outputs: the first sample of each interval).
    cycle_ends : ndarray
        Times at which a cycle ends (channel-1 starts after the first).
    alpha, e0 : float
    rate : float or None
    segments : list of Segment
        Continuous outputs: the active intervals of the schedule (empty for sampled outputs).
    y : list of ndarray or None
        Sampled outputs only: the sample ``y_k`` (with noise) taken at ``t[k]``.
    """

    t: np.ndarray
    x: np.ndarray
    x_hat: np.ndarray
    error: np.ndarray
    channel: np.ndarray
    z: np.ndarray
    paper_bound: np.ndarray
    exact_bound: np.ndarray
    xo_norms: np.ndarray
    switching_times: np.ndarray
    cycle_ends: np.ndarray
    alpha: float
    e0: float
    rate: float | None
    segments: list = field(default_factory=list, repr=False)
    hold_bound: np.ndarray | None = None
    y: list | None = field(default=None, repr=False)
    family: str = "lmi"
    noise_bound: np.ndarray | None = None
    noisy: bool = False

    @property
    def paper(self) -> bool:
        """Whether the paper's envelopes apply to the gains of this run (its LMI family)."""
        return paper_gains(self.family)

    @property
    def error_norm(self) -> np.ndarray:
        """``||x_tilde(t)||``, shape (T,)."""
        return np.linalg.norm(self.error, axis=1)

    def at(self, t: float) -> int:
        """Index of the last output time <= t."""
        return int(np.searchsorted(self.t, t, side="right") - 1)

    def guarantee(self) -> tuple[np.ndarray | None, str, str]:
        """The bound this run can honestly call guaranteed: ``(values, label, status)``.

        ``label`` names the column in one phrase ("guaranteed bound", "noise-free bound", ...);
        ``status`` says what it is and whether it held at every output (violations are counted
        with a relative tolerance of 1e-9; any violation makes it "NOT verified").

        - A declared noise bound (``noise_max``): the observer's ``noise_bound``.
        - Measurement hold: ``hold_bound`` (exact arithmetic; the plant-driven term included).
        - Noise without a declared bound: the exact bound is the *noise-free* bound, never
          called guaranteed (measurement noise: declare ``noise_max`` for a guarantee).
        - Otherwise: the exact bound, rounding included (:mod:`switchobs_core.numerics.rounding`).
        """
        en = self.error_norm

        def checked(b: np.ndarray, what: str) -> str:
            bad = en > b * (1 + 1e-9) + 1e-300
            n_bad = int(np.sum(bad))
            if n_bad:
                return (f"{what}: NOT verified: below the error at {n_bad} of {len(self.t)} outputs "
                        f"from t = {float(self.t[np.argmax(bad)]):.3g} s")
            return f"{what}: verified at all {len(self.t)} outputs"

        if self.noise_bound is not None:
            return self.noise_bound, "guaranteed bound (bounded noise)", checked(
                self.noise_bound, "||Phi|| e0 plus the declared noise's worst case, rounding included")
        if self.hold_bound is not None and self.paper and not self.noisy:
            return self.hold_bound, "guaranteed bound", checked(
                self.hold_bound, "||Phi_ee|| e0 + ||Phi_ex|| ||x(0)|| (measurement hold, noise-free, u = 0, "
                "exact arithmetic)")
        if self.noisy:
            return self.exact_bound, "noise-free bound", (
                "||Phi|| e0, the bound for noise-free outputs: NOT a guarantee for this run, whose outputs "
                "or plant are noisy (declare a measurement-noise bound, --noise-max, for one)")
        where = ("continuous outputs" if self.rate is None else "sampled outputs, innovation hold"
                 if self.paper else f"sampled outputs, {self.family} gains")
        return self.exact_bound, "guaranteed bound", checked(
            self.exact_bound, f"||Phi|| e0 with the computation's rounding ({where}, noise-free)")

    def summary(self) -> dict:
        """JSON-ready summary: final error, bounds and violations of the paper's bound."""
        en = self.error_norm
        paper = self.paper      # the paper's envelopes are for its LMI gains only
        viol = [int(np.sum(self.xo_norms[i] > self.z[i] * (1 + 1e-9))) for i in range(self.z.shape[0])]
        ends = [self.at(tc) for tc in self.cycle_ends]
        out = {
            "t_end": float(self.t[-1]),
            "rate_hz": self.rate,
            "e0": self.e0,
            "alpha": self.alpha,
            "final_error": float(en[-1]),
            "final_paper_bound": float(self.paper_bound[-1]),
            "final_exact_bound": float(self.exact_bound[-1]),
            # counted in every mode, with the tolerance stated here (relative 1e-9)
            "exact_bound_violations": int(np.sum(en > self.exact_bound * (1 + 1e-9) + 1e-300)),
            "paper_bound_violations": int(np.sum(en > self.paper_bound * (1 + 1e-9))),
            "envelope_violations": viol,
            "max_envelope_ratio": [float(np.max(self.xo_norms[i] / np.maximum(self.z[i], 1e-300)))
                                   for i in range(self.z.shape[0])],
            "cycle_end_errors": [float(en[j]) for j in ends],
            "cycles": len(self.cycle_ends),
            "gain_family": self.family,
            "noisy": self.noisy,
            "final_noise_bound": None if self.noise_bound is None else float(self.noise_bound[-1]),
            "noise_bound_violations": None if self.noise_bound is None else
            int(np.sum(en > self.noise_bound * (1 + 1e-9) + 1e-300)),
        }
        if not paper:
            for key in ("final_paper_bound", "paper_bound_violations", "envelope_violations", "max_envelope_ratio"):
                out[key] = None
        return out
