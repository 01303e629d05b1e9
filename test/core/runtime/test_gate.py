"""switchobs_core.runtime.gate: the chi-square gate on the normalised innovation nu' (C P C' + R)^-1 nu."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.stats import chi2

from switchobs_core.exceptions import InvalidArgument
from switchobs_core.runtime.gate import ChiSquareGate, GateResult, chi2_gate, nis


def _spd(rng: np.random.Generator, n: int, cond: float) -> np.ndarray:
    """A symmetric positive definite n x n matrix of condition number ``cond``."""
    Q, _ = np.linalg.qr(rng.standard_normal((n, n)))
    return (Q * np.geomspace(1.0, 1.0 / cond, n)) @ Q.T


@settings(max_examples=200, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), p=st.integers(1, 6), n=st.integers(1, 12),
       scale=st.sampled_from([1e-6, 1.0, 1e4]), cond=st.sampled_from([1.0, 1e3, 1e6]))
def test_nis_is_the_normalised_innovation_squared(seed, p, n, scale, cond):
    """Any C, P, R, x_hat, y: the gate's NIS equals nu' S^-1 nu computed through the Cholesky
    factor of S (an independent route), to a relative 1e-8 of the conditioning allowed here."""
    rng = np.random.default_rng(seed)
    C = rng.standard_normal((p, n))
    P = _spd(rng, n, cond) * scale**2
    R = np.diag(rng.uniform(0.1, 2.0, p)) * scale**2
    x = rng.standard_normal(n) * scale
    y = C @ x + rng.standard_normal(p) * scale
    v = nis(C, P, R, x, y)
    S = C @ P @ C.T + R
    w = np.linalg.solve(np.linalg.cholesky(0.5 * (S + S.T)), y - C @ x)
    assert v >= 0.0
    assert v == pytest.approx(float(w @ w), rel=1e-8, abs=1e-300)
    # the gate reads the same number for the channel's rows, and compares it with its threshold
    gate = ChiSquareGate([C], 0.05)
    g = gate.check(1, None, y, x, P, R)
    assert g.nis == v and g.rows == p and g.threshold == chi2_gate(p, 0.05)
    assert g.ok == (v <= g.threshold)


@settings(max_examples=100, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(2, 10), k=st.integers(1, 4))
def test_rows_select_the_sample_rows_of_the_channel(seed, n, k):
    """A sample holding some rows of a channel is gated as y = C_r x + v with C_r those rows."""
    rng = np.random.default_rng(seed)
    C1, C2 = rng.standard_normal((5, n)), rng.standard_normal((5, n))
    rows = tuple(sorted(rng.choice(5, size=k, replace=False).tolist()))
    P = _spd(rng, n, 10.0)
    R = np.diag(rng.uniform(0.1, 1.0, k))
    x = rng.standard_normal(n)
    y = rng.standard_normal(k)
    g = ChiSquareGate([C1, C2], 0.01).check(2, rows, y, x, P, R)
    assert g.channel == 2 and g.rows == k
    assert g.nis == nis(C2[list(rows)], P, R, x, y)


@pytest.mark.parametrize("p", [1, 2, 4, 12])
@pytest.mark.parametrize("alpha", [1e-6, 0.01, 0.05, 0.5])
def test_threshold_is_the_upper_quantile(p, alpha):
    assert chi2_gate(p, alpha) == pytest.approx(chi2.ppf(1.0 - alpha, p), rel=1e-9)
    gate = ChiSquareGate([np.eye(p)], alpha)
    assert gate.threshold(p) == chi2_gate(p, alpha) and gate.threshold(p) is gate.threshold(p)


def test_false_alarm_rate_is_alpha_when_the_model_holds():
    """Samples drawn from the noise model, prior error drawn from P: the gate rejects a share
    alpha of them (20 000 samples: alpha = 0.05 within 5 sigma, sigma = 0.15 %)."""
    rng = np.random.default_rng(7)
    n, p, alpha, K = 6, 3, 0.05, 20_000
    C = rng.standard_normal((p, n))
    P = _spd(rng, n, 100.0)
    R = np.diag([0.5, 1.0, 2.0])
    gate = ChiSquareGate([C], alpha)
    LP, LR = np.linalg.cholesky(P), np.linalg.cholesky(R)
    rejected = 0
    for _ in range(K):
        x = rng.standard_normal(n)
        x_hat = x - LP @ rng.standard_normal(n)
        y = C @ x + LR @ rng.standard_normal(p)
        rejected += not gate.check(1, None, y, x_hat, P, R).ok
    sigma = np.sqrt(alpha * (1 - alpha) / K)
    assert abs(rejected / K - alpha) < 5 * sigma, rejected / K


def test_describe_names_the_numbers():
    g = GateResult(channel=2, nis=12.5, threshold=9.49, rows=4, alpha=0.05)
    assert not g.ok
    assert g.describe() == "NIS 12.5 > 9.49 (chi-square, 4 rows, alpha 0.05)"
    assert GateResult(1, 9.49, 9.49, 4, 0.05).ok


def test_scipy_special_imported_only_with_the_gate_on():
    """The gate's module and a gate made with ``alpha = 0`` (the estimator's start without the gate)
    leave ``scipy.special`` unimported; a gate made with ``alpha > 0`` imports it and holds its channels'
    thresholds, ``chdtri``'s numbers byte for byte."""
    import json
    import subprocess
    import sys

    probe = (
        "import json, sys\n"
        "import numpy as np\n"
        "from switchobs_core.runtime.gate import ChiSquareGate\n"
        "off = ChiSquareGate([np.eye(3), np.eye(2)], 0.0)\n"
        "before = 'scipy.special' in sys.modules\n"
        "on = ChiSquareGate([np.eye(3), np.eye(2)], 0.01)\n"
        "after = 'scipy.special' in sys.modules\n"
        "from scipy.special import chdtri\n"
        "same = on._thresholds == {3: float(chdtri(3, 0.01)), 2: float(chdtri(2, 0.01))}\n"
        "print(json.dumps([before, after, same, on.threshold(1) == float(chdtri(1, 0.01))]))\n")
    res = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, timeout=120)
    assert res.returncode == 0, res.stderr
    assert json.loads(res.stdout) == [False, True, True, True]


@pytest.mark.parametrize("alpha", [1.0, 1.5, float("nan"), -0.01, float("inf")])
def test_a_rate_outside_0_1_is_refused(alpha):
    """A rate of 1 or more or NaN would give NaN thresholds that reject every sample ("NIS 0 > nan"), a
    negative one would turn the gate off: refused when the gate is made, naming the range."""
    with pytest.raises(InvalidArgument, match=r"alpha must be in \[0, 1\)"):
        ChiSquareGate([np.eye(2)], alpha)
    assert ChiSquareGate([np.eye(2)], 0.0).alpha == 0.0       # 0: no gate
