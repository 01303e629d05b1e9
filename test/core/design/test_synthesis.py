"""LMI synthesis (Lemma t:observer-sdp-design), gain verification and kappa curves."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest
from scipy.linalg import expm

from switchobs_core.design.synthesis import KappaCurve, LMISynthesizer, verify_gain
from switchobs_core.exceptions import InvalidArgument, VerificationError
from switchobs_core.paper import kappa_closed_form


@pytest.fixture(scope="module")
def synths(paper):
    return [LMISynthesizer(d.A_o, d.C_o) for d in paper.decompositions]


@pytest.mark.parametrize("channel", [1, 2])
def test_kappa_matches_closed_form(synths, channel):
    # DESIGN.md: kappa_i(eta) = a + sqrt(1 + a^2), a = eta + d_i (an independent oracle).
    for eta in np.linspace(0.1, 6.0, 12):
        kappa = np.sqrt(synths[channel - 1].theta_star(eta))
        assert kappa == pytest.approx(kappa_closed_form(eta, channel), rel=1e-6)


@pytest.mark.parametrize("channel, eta", [(1, 1.6), (2, 3.5), (1, 0.3), (2, 6.0)])
def test_gain_meets_its_bound_independently(synths, paper, channel, eta):
    g = synths[channel - 1].gain(eta)
    d = paper.decomposition(channel)
    Lam = d.A_o - g.L_o @ d.C_o
    # spectral abscissa below -eta
    assert np.max(np.linalg.eigvals(Lam).real) < -eta
    # ||e^{Lambda t}|| <= kappa e^{-eta t} (e:error_bound), checked with scipy's expm
    for t in np.linspace(0.0, 5.0, 26):
        assert np.linalg.norm(expm(Lam * t), 2) <= g.kappa * np.exp(-eta * t) * (1 + 1e-9)
    # the reported kappa is within the documented slack of the optimum
    assert kappa_closed_form(eta, channel) <= g.kappa <= kappa_closed_form(eta, channel) * (1 + 1e-4)
    assert g.eta_verified >= eta


def test_gains_do_not_depend_on_solve_order(paper):
    d = paper.decomposition(1)
    a, b = LMISynthesizer(d.A_o, d.C_o), LMISynthesizer(d.A_o, d.C_o)
    ga1, ga2 = a.gain(1.6), a.gain(3.5)
    gb2, gb1 = b.gain(3.5), b.gain(1.6)
    assert np.array_equal(ga1.L_o, gb1.L_o) and np.array_equal(ga2.L_o, gb2.L_o)


def test_kappa_curve_is_function_of_eta_only(paper):
    d = paper.decomposition(2)
    c1 = KappaCurve(LMISynthesizer(d.A_o, d.C_o))
    c2 = KappaCurve(LMISynthesizer(d.A_o, d.C_o))
    etas = [0.5, 2.3, 1.1, 4.0]
    v1 = [c1.kappa(e) for e in etas]
    v2 = [c2.kappa(e) for e in reversed(etas)][::-1]
    assert v1 == v2
    e, k = c1.points()
    assert np.all(np.diff(k) >= 0) and np.all(np.diff(e) > 0)


def test_verify_gain_rejects_a_bad_gain(paper):
    d = paper.decomposition(1)
    L = np.zeros((d.r, d.C_o.shape[0]))  # no correction: A_o is not Hurwitz
    with pytest.raises(VerificationError, match="certifies decay rate"):
        verify_gain(d.A_o, d.C_o, L, np.eye(d.r), 0.5)
    with pytest.raises(VerificationError, match="not positive definite"):
        verify_gain(d.A_o, d.C_o, L, -np.eye(d.r), 0.5)


def test_bad_arguments_raise_own_errors(synths):
    with pytest.raises(InvalidArgument, match="eta must be >= 0"):
        synths[0].theta_star(-1.0)
    with pytest.raises(InvalidArgument, match="eta must be finite"):
        synths[0].gain(float("nan"))
    with pytest.raises(InvalidArgument, match="A_o has a non-finite entry"):
        LMISynthesizer([[np.inf]], [[1.0]])
    with pytest.raises(InvalidArgument, match="C_o has the wrong number of columns"):
        LMISynthesizer(np.eye(2), [[1.0, 0.0, 0.0]])


@pytest.mark.parametrize("channel", [1, 2])
def test_conic_form_equals_the_cvxpy_form(paper, channel):
    """Clarabel on the hand-written conic form and Clarabel through cvxpy solve the same problem:
    theta* agrees to 1e-6 (relative) over the eta grid the designs scan, in the plain and a
    rescaled form, and the least-norm (P, Y) of stage 2 agrees to 1e-4."""
    from switchobs_core.design.synthesis import KAPPA_GRID, _ScaledSDP

    d = paper.decomposition(channel)
    for scale in (np.ones(d.A_o.shape[0]), np.linspace(0.5, 2.0, d.A_o.shape[0])):
        form = _ScaledSDP(d.A_o, d.C_o, scale)
        for eta in [float(e) for e in KAPPA_GRID[:50:7]]:
            form.set_eta(eta)
            assert form.solve_conic(1) == "optimal"
            direct = form.theta_value
            assert form.solve_cvxpy(1, "CLARABEL", {}) == "optimal"
            assert direct == pytest.approx(form.theta_value, rel=1e-6), eta
        form.set_eta(3.5)
        form.solve_conic(1)
        form.theta_cap = form.theta_value * 1.0001
        assert form.solve_conic(2) == "optimal"
        P1, Y1 = form.point()
        assert form.solve_cvxpy(2, "CLARABEL", {}) == "optimal"
        P2, Y2 = form.point()
        assert np.linalg.norm(np.hstack([P1 - P2, Y1 - Y2])) <= 1e-4 * np.linalg.norm(np.hstack([P2, Y2]))


def test_cvxpy_is_the_fallback_when_the_direct_solve_fails(paper, monkeypatch):
    """A direct Clarabel solve that fails hands the problem to cvxpy (Clarabel, then SCS): the
    gain is the same to the solver's tolerance and still verified."""
    from switchobs_core.design import synthesis

    d = paper.decomposition(1)
    direct = LMISynthesizer(d.A_o, d.C_o).gain(1.6)
    monkeypatch.setattr(synthesis._ScaledSDP, "solve_conic", lambda self, stage: "error (made to fail)")
    syn = LMISynthesizer(d.A_o, d.C_o)
    g = syn.gain(1.6)
    assert g.solver == "CLARABEL" and g.eta_verified >= 1.6
    assert g.kappa == pytest.approx(direct.kappa, rel=1e-5)
    assert np.allclose(g.L_o, direct.L_o, rtol=1e-4, atol=1e-6)
    with pytest.raises(synthesis.DesignError, match=r"did not solve \(SCS: "):
        monkeypatch.setattr(synthesis._ScaledSDP, "solve_cvxpy", lambda self, stage, s, o: "infeasible")
        syn.theta_star(2.0)


def test_a_design_does_not_import_cvxpy():
    """The LMI design of a cycle runs without the modelling layer (its import is most of a
    `switchobs plan`): cvxpy is imported only for a fallback."""
    code = ("import sys\nfrom switchobs_core.design.lmi import Designer\n"
            "from switchobs_core.model.scenarios import paper_system\nfrom switchobs_core.model.schedule import Cycle\n"
            "d = Designer(paper_system()).design(Cycle.from_ts(1.0, 0.5))\n"
            "print(d.certified, 'cvxpy' in sys.modules)")
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr
    assert res.stdout.split() == ["True", "False"]
