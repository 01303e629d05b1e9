"""Certificates: the paper's cycle factors beside sound, verified ones (Sections 4-6).

*The paper's certificate* (Theorem ``t:main``): per cycle the factors
``f_ii = kappa_i exp(mu_i (tau - h_i) - eta_i h_i)`` (e:Fk, e:f11_le_delta_main) and the
claim ``||F_k|| <= delta < 1``. Its proof has a gap: while channel j is
active the observable error of channel i != j is also driven by ``-T_io' L_j C_j
x_tilde``, which (e:xo1_dynamics_piecewise) omits. The factors are reported as *the
paper's claim*; :func:`envelope_ratio` measures how far its envelopes are exceeded.

*Sound certificates* (ours, verified in floating point). They are for the paper's
continuous-output setting: products of ``expm((A - L_i C_i) h_i)``. A sampled observer with
innovation hold applies ``e^{A dt} - Gamma_A L C`` per sample instead, which equals
``expm((A - L C) dt)`` up to O(dt^2); measured on the paper's (2 s, 0.6) design the cycle
spectral radius is 0.4868 continuous, 0.4799 at 100 Hz and 0.4005 at 10 Hz, but these
certificates do not prove the sampled case.

* :func:`cycle_transition` -- the exact error map over one cycle,
  ``Phi = expm((A - L_N C_N) h_N) ... expm((A - L_1 C_1) h_1)`` (from
  e:xtilde_dyn_piecewise); a periodic schedule converges iff its spectral radius is < 1,
  and ``||x_tilde(t_{k+1})|| <= ||Phi|| ||x_tilde(t_k)||``.
* :func:`common_lyapunov` -- for a finite set of cycle types, ``P >= I`` with
  ``Phi_j' P Phi_j <= rho^2 P`` for all j, so ``||x_tilde(t_k)|| <= sqrt(cond P) rho^k
  ||x_tilde(0)||`` for *any* order of those cycles.
* :func:`certify_box` -- robust designs: every schedule with residence times in
  ``[h_min, h_max]`` (A2), proved with multiple Lyapunov functions and a rigorous
  remainder between grid points (the argument is in its docstring).


Modules: :mod:`.paper` (the paper's factors, envelope ratio), :mod:`.cycle` (cycle maps),
:mod:`.lyapunov` (common Lyapunov SDP), :mod:`.box` (residence-time box proof),
:mod:`.report` (whole-table certificates and their report). Everything public is re-exported
here: ``from switchobs_core.certificate import X``.

Paper labels (``e:...``, ``t:...``) resolve to numbers in ``docs/equations.md``.
"""

from __future__ import annotations

from .box import BoxCertificate, certify_box
from .cycle import CycleCertificate, certify_cycle, cycle_transition
from .lyapunov import LyapunovCertificate, common_lyapunov
from .paper import EnvelopeRatio, cycle_factor, envelope_ratio, paper_factors
from .report import TableReport as TableReport  # the record certify_table returns
from .report import certify_table, format_report

__all__ = [
    "cycle_factor",
    "paper_factors",
    "cycle_transition",
    "CycleCertificate",
    "certify_cycle",
    "LyapunovCertificate",
    "common_lyapunov",
    "BoxCertificate",
    "certify_box",
    "EnvelopeRatio",
    "envelope_ratio",
    "certify_table",
    "format_report",
]
