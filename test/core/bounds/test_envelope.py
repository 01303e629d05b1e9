"""Tests of switchobs_core.bounds.envelope: alpha, the paper's z_i recursions, exact transitions."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest
from scipy.linalg import expm

from switchobs_core.bounds.envelope import EnvelopeTracker, Segment, alpha, envelope_z, error_transitions
from switchobs_core.exceptions import InvalidArgument


def test_alpha_hand_computed():
    # H = [[1, 0], [1/sqrt2, 1/sqrt2]]: H'H has eigenvalues 1 +- sqrt(1/2)
    T1 = np.array([[1.0], [0.0]])
    T2 = np.array([[1.0], [1.0]]) / math.sqrt(2)
    assert alpha([T1, T2]) == pytest.approx(1 / math.sqrt(1 - math.sqrt(0.5)), rel=1e-12)


def test_alpha_rank_deficient():
    T = np.array([[1.0], [0.0]])
    with pytest.raises(InvalidArgument, match="A1"):
        alpha([T, T])


def test_alpha_paper_model(paper):
    # camera states are observable in both channels, agents in one each: H'H = diag(2,..,1,..) -> alpha = 1
    assert alpha([paper.decomposition(i).T_o for i in (1, 2)]) == pytest.approx(1.0, abs=1e-12)


def _design(kappa, eta, mu, L=None):
    return SimpleNamespace(kappa=kappa, eta=eta, mu=mu, L=L)


def test_envelope_z_closed_form():
    d = _design((2.0, 3.0), (1.0, 2.0), (0.5, 0.25))
    segs = [Segment(0.0, 1.0, 1, d), Segment(1.0, 3.0, 2, d), Segment(3.0, 4.0, 1, d)]
    t = np.array([0.0, 0.5, 1.0, 2.0, 3.5])
    z = envelope_z(t, segs, 0.7)
    e0 = 0.7
    z1_1 = 2 * math.exp(-1.0) * e0          # end of channel 1's first interval
    z2_1 = math.exp(0.25) * e0
    z1_3 = math.exp(0.5 * 2) * z1_1          # channel 1 inactive on [1, 3)
    expect1 = [2 * e0, 2 * math.exp(-0.5) * e0, z1_1, math.exp(0.5) * z1_1, 2 * math.exp(-0.5) * z1_3]
    z2_3 = 3 * math.exp(-4.0) * z2_1
    expect2 = [e0, math.exp(0.125) * e0, 3 * z2_1, 3 * math.exp(-2.0) * z2_1, math.exp(0.125) * z2_3]
    np.testing.assert_allclose(z[0], expect1, rtol=1e-13)
    np.testing.assert_allclose(z[1], expect2, rtol=1e-13)


def test_tracker_fk_recursion():
    # Z_{k+1} = F_k Z_k (e:Fz_system) with f_ii = kappa_i exp(mu_i (tau - h_i) - eta_i h_i)
    kappa, eta, mu, h = (1.5, 2.0), (2.0, 3.0), (0.6, 0.5), (1.2, 0.8)
    tr = EnvelopeTracker(mu, 1.0)
    t = 0.0
    for _ in range(3):
        for ch in (1, 2):
            tr.switch(t, ch, kappa, eta)
            t += h[ch - 1]
    f = [kappa[i] * math.exp(mu[i] * (2.0 - h[i]) - eta[i] * h[i]) for i in range(2)]
    np.testing.assert_allclose(tr.z(t), np.array(f) ** 3, rtol=1e-12)


def test_error_transitions_match_expm_product():
    rng = np.random.default_rng(3)
    A = rng.standard_normal((3, 3))
    C = (rng.standard_normal((1, 3)), rng.standard_normal((1, 3)))
    d = _design((1, 1), (1, 1), (0, 0), L=(rng.standard_normal((3, 1)), rng.standard_normal((3, 1))))
    segs = [Segment(0.0, 0.4, 1, d), Segment(0.4, 1.0, 2, d), Segment(1.0, 2.0, 1, d)]
    t = np.array([0.0, 0.3, 0.7, 1.5])
    Ph = error_transitions(A, C, t, segs)
    M1, M2 = A - d.L[0] @ C[0], A - d.L[1] @ C[1]
    expect = [np.eye(3), expm(M1 * 0.3), expm(M2 * 0.3) @ expm(M1 * 0.4),
              expm(M1 * 0.5) @ expm(M2 * 0.6) @ expm(M1 * 0.4)]
    for P, E in zip(Ph, expect):
        np.testing.assert_allclose(P, E, rtol=1e-11, atol=1e-13)


def test_envelope_init_takes_the_dataclass_fields_in_order_with_their_defaults():
    """``Envelope`` writes its ``__init__`` by hand (half the dataclass's cost per sample): its parameters
    are the dataclass's fields, in order, with the same defaults, so ``replace`` and pickling keep working
    when a field is added to one of them."""
    import dataclasses
    import inspect

    from switchobs_core.bounds.envelope import Envelope

    params = list(inspect.signature(Envelope.__init__).parameters.values())[1:]
    fields = dataclasses.fields(Envelope)
    assert [p.name for p in params] == [f.name for f in fields]
    for p, f in zip(params, fields):
        want = f.default if f.default is not dataclasses.MISSING else inspect.Parameter.empty
        assert p.default == want or (p.default is want), (p.name, p.default, want)
