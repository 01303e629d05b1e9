"""Audit of the rigorous bounds: the published exact bound and noise bound are
never below the error of the *computed* estimate, on systems, rates and stamps that
test_rounding.py (the paper's model at 30 and 100 Hz, random corner noise) does not cover.

Cases, each for the LMI family and the ``kalman`` table (``rounding_bound`` on, the default):

* a mode at +1.5/s whose state norm reaches 1e11 (``unstable15``);
* a stiff system with eigenvalues -0.1 and -500 (``stiff``);
* two coupled lightly damped oscillators (``osc``, test/core/_systems.py);
* 1 kHz; +-30 % jitter on every stamp; sample times that are not whole nanoseconds (k / 30);
  Unix-time stamps (t ~ 1.7e9 s: one ulp is 0.24 us, so every step is off the nanosecond grid);
  a late start (the observer starts at t0 = 0, its first sample comes 1.38 s later, mid-cycle);
* bounded noise at a declared ``noise_max`` chosen by an adversary: ``v = v_max sign(C e)`` with
  ``e`` the prior error (the innovation pushed outwards), a constant corner of the box, and a
  square wave between two opposite corners (period 0.7 s). Here the noise bound is checked.

At every sample the error ``||x_hat - x||`` against the true state is checked against the bound
published after the update (``envelope()``), against the prior sets of ``prior(t)`` before it, and
every 10th sample against ``envelope(t)`` and ``predict(t, hold=True)`` half-way to the next sample.

The truth (``_extended_truth.py``). ``np.longdouble`` on x86-64 (the x87 80-bit format, unit
roundoff 5.4e-20, 2^11 times finer than double): the state is propagated between samples with
Taylor polynomials of ``A h`` (``||A h|| <= 1/4``, the degree from a proven remainder bound below the
unit roundoff), written there, independent of the library's exponentials; the plant starts from an
exact double ``x0`` and each output is ``C x (+ v)`` rounded once to double. Why that is enough: the
truth is computed twice, with two substep sizes, and their distance ``delta`` (the truth's own
rounding, 1e-19 relative per substep) is asserted to be below 1e-3 of the bound at every sample,
and added to the error before the comparison. The double-precision estimate's error is at least
the output rounding (1.1e-16 relative), so a longdouble truth resolves it; mpmath is not a
dependency of the project. On a platform whose ``longdouble`` is plain double the test skips.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pytest
from _extended_truth import Truth
from _systems import oscillators

import switchobs_core as so
from switchobs_core.bounds.kalman_map import SparseTransition

pytestmark = pytest.mark.skipif(np.finfo(np.longdouble).eps > 2.0**-60,
                                reason="needs an extended-precision longdouble (x86 80-bit or quad)")

LD = np.longdouble
NOISE_MAX = 1e-3


def _systems() -> dict:
    """name -> (system, cycle, true x0). Every estimate starts at zero, so e0 = ||x0||."""
    unstable = so.LTISystem(np.array([[1.5, 0.3, 0.0], [0.0, 0.0, 1.0], [0.0, -4.0, -0.2]]), None,
                            [np.array([[0.0, 1.0, 0.0]]), np.array([[1.0, 0.0, 0.0]])], name="unstable15")
    stiff = so.LTISystem(np.array([[-0.1, 1.0], [0.0, -500.0]]), None,
                         [np.array([[1.0, 0.0]]), np.array([[0.0, 1.0]])], name="stiff")
    # n >= 40: the Kalman sample's factored ellipsoid step (kalman_map) and the Cholesky-verified
    # amortised read (bound_read) are what envelope() publishes there
    blocks = np.kron(np.eye(14), unstable.A)
    pick = [np.kron(np.eye(14), Ci) for Ci in unstable.C]
    blocks14 = so.LTISystem(blocks, None, pick, name="blocks14")
    agents = so.camera_agents(10)
    rng = np.random.default_rng(11)
    xa = np.zeros(agents.n)
    xa[0::4], xa[1::4] = rng.uniform(-2, 2, 11), rng.uniform(-2, 2, 11)
    return {
        "blocks14": (blocks14, so.Cycle((0.6, 0.4)), np.tile([1.0, 1.0, 0.0], 14)),
        "agents10": (agents, so.Cycle((0.1,) * 10), xa),
        "unstable15": (unstable, so.Cycle((0.6, 0.4)), np.array([1.0, 1.0, 0.0])),
        "stiff": (stiff, so.Cycle((0.3, 0.2)), np.array([2.0, -3.0])),
        "osc": (oscillators(), so.Cycle((0.61, 0.39)), np.array([0.5, -1.0, 0.3, 2.0])),
    }


SYSTEMS = _systems()


@dataclass(frozen=True)
class Case:
    system: str
    rate: float = 50.0
    seconds: float = 10.0
    stamps: str = "grid"        # grid | jitter | unix | late
    noise: str = ""             # "" (exact bound) | sign | corner | square (noise bound)
    slow: bool = False
    families: tuple = ("lmi", "kalman")

    @property
    def id(self) -> str:
        return "-".join(str(v) for v in (self.system, f"{self.rate:g}Hz", self.stamps, self.noise or "exact") if v)


CASES = [
    Case("unstable15", seconds=17.5),                       # ||x|| from 1.4 to 2e11
    Case("stiff", seconds=2.0),
    Case("osc", seconds=4.0),
    Case("osc", rate=30.0, seconds=4.0),                    # k / 30: no step is a whole number of ns
    Case("osc", stamps="unix", seconds=4.0),
    Case("osc", stamps="late", seconds=4.0),
    Case("osc", stamps="jitter", seconds=4.0),
    Case("osc", noise="sign", seconds=4.0),
    Case("osc", noise="corner", seconds=4.0),
    Case("osc", noise="square", seconds=4.0),
    Case("unstable15", noise="sign", seconds=17.5, slow=True),
    Case("stiff", stamps="jitter", noise="sign", seconds=4.0, slow=True),
    Case("osc", rate=1000.0, seconds=5.0, slow=True),
    Case("osc", rate=1000.0, stamps="jitter", noise="sign", seconds=3.0, slow=True),
    Case("unstable15", stamps="unix", seconds=17.5, slow=True),
    Case("unstable15", stamps="late", seconds=17.5, slow=True),
    # n = 42 and 44 (module docstring of kalman_map): the Kalman families only (no LMI design at this size)
    Case("blocks14", seconds=17.5, families=("kalman", "kalman-online")),
    Case("agents10", seconds=4.0, families=("kalman", "kalman-online", "lmi")),
    Case("agents10", noise="sign", seconds=4.0, families=("kalman", "kalman-online", "lmi")),
    Case("agents10", stamps="jitter", noise="corner", seconds=3.0, families=("kalman",)),
]


def stamps(case: Case, rng: np.random.Generator) -> tuple[float, list[float]]:
    """(observer t0, sample stamps) of a case, the plant starting at t0."""
    K = int(round(case.seconds * case.rate)) + 1
    k = np.arange(K)
    if case.stamps == "unix":
        T0 = 1_700_000_000.123456
        return T0, [T0 + i / case.rate for i in k]
    if case.stamps == "jitter":      # +-30 % of a period on every stamp but the first
        t = k / case.rate + rng.uniform(-0.3, 0.3, K) / case.rate
        t[0] = 0.0
        return 0.0, [float(v) for v in t]
    if case.stamps == "late":
        return 0.0, [float(v) for v in k / case.rate if v >= 1.37]
    return 0.0, [float(v) for v in k / case.rate]


def _noise(case: Case, t: float, C: np.ndarray, e_prior: np.ndarray, corner: np.ndarray) -> np.ndarray:
    """The adversary's noise, inside the box ``|v_j| <= NOISE_MAX`` (module docstring)."""
    if case.noise == "sign":
        return NOISE_MAX * np.sign(C @ e_prior)
    if case.noise == "corner":
        return NOISE_MAX * corner[: C.shape[0]]
    if case.noise == "square":
        return NOISE_MAX * corner[: C.shape[0]] * (1.0 if math.sin(2 * math.pi * t / 0.7) >= 0 else -1.0)
    return np.zeros(C.shape[0])


def _lam_max(S: np.ndarray) -> float:
    """``lambda_max`` of a shape matrix, with a relative allowance for the eigenvalue solver."""
    S = 0.5 * (S + S.T)
    return float(np.linalg.eigvalsh(S)[-1]) * (1 + 1e-10) + S.shape[0] * 1e-15 * float(np.linalg.norm(S))


def _prior_bound(S) -> float:
    """The norm bound of a prior set of ``prior(t)``: an ellipsoid's shape matrix or a float."""
    return math.sqrt(_lam_max(S)) if isinstance(S, np.ndarray) else float(S)


def audit(case: Case, family: str, table: so.GainTable) -> dict:
    """Run one case; count samples whose error (plus the truth's ``delta``) exceeds a bound."""
    system, cycle, x0 = SYSTEMS[case.system]
    rng = np.random.default_rng(7)
    t0, ts = stamps(case, rng)
    corner = rng.choice([-1.0, 1.0], size=max(system.p))
    sched = so.PeriodicSchedule(cycle)
    e0 = float(np.linalg.norm(x0)) * (1 + 1e-12)
    obs = so.SwitchedObserver(system, table, "periodic", [cycle], t0=t0, e0=e0,
                              noise_max=NOISE_MAX if case.noise else None,
                              **({"family": family} if family == "kalman-online" else {}))
    truth = Truth(system.A, x0)
    C = [np.asarray(Ci, dtype=LD) for Ci in system.C]
    out = {"violations": 0, "checks": 0, "worst": 0.0, "delta_ratio": 0.0, "first": None}

    def check(err: float, bound: float, where: str) -> None:
        out["checks"] += 1
        d = truth.delta
        out["delta_ratio"] = max(out["delta_ratio"], d / bound if bound > 0 else math.inf)
        out["worst"] = max(out["worst"], (err + 4 * d) / bound if bound > 0 else math.inf)
        if err + 4 * d > bound:
            out["violations"] += 1
            out["first"] = out["first"] or f"{where}: error {err:.6g} + 4 delta {4 * d:.3g} > bound {bound:.6g}"

    def err_of(xh: np.ndarray, x: np.ndarray) -> float:
        return float(np.linalg.norm((np.asarray(xh, dtype=LD) - x).astype(float)))

    t_prev, max_x = t0, float(np.linalg.norm(x0))
    for k, t in enumerate(ts):
        truth.advance(LD(t) - LD(t_prev))
        max_x = max(max_x, float(np.linalg.norm(truth.x.astype(float))))
        t_prev = t
        ch = sched.channel_at(t - t0)
        x_prior, S_exact, S_noise = obs.prior(t)
        e_prior = np.asarray(x_prior, dtype=LD) - truth.x
        e_p = err_of(x_prior, truth.x)
        check(e_p, _prior_bound(S_noise if case.noise else S_exact), f"prior at t = {t!r}")
        v = _noise(case, t, system.C[ch - 1], e_prior.astype(float), corner)
        y = np.asarray(C[ch - 1] @ truth.x + np.asarray(v, dtype=LD), dtype=float)
        xh = obs.update(t, ch, y)
        env = obs.envelope()
        bound = env.noise_bound if case.noise else env.exact_bound
        check(err_of(xh, truth.x), bound, f"sample {k} at t = {t!r}")
        if k % 10 == 0 and k + 1 < len(ts):
            tm = t + 0.5 * (ts[k + 1] - t)
            env_m = obs.envelope(tm)
            x_m = truth.at(LD(tm) - LD(t))
            check(err_of(obs.predict(tm, hold=True), x_m), env_m.noise_bound if case.noise else env_m.exact_bound,
                  f"between samples at t = {tm!r}")
    b = obs._bound
    out.update(factored=any(getattr(m, "_sp", None) is not None
                            for m in getattr(obs._gains, "_fused", {}).values())
               or any(isinstance(getattr(e, "sparse", None), SparseTransition)
                      or isinstance(getattr(e, "sparse_E", None), SparseTransition) for e in obs._cache._lru.values()),
               verified=(b._readv if case.noise else b._read).verified,
               anchors=(b._readv if case.noise else b._read).anchors)
    out.update(samples=len(ts), error=err_of(obs.x_hat, truth.x), bound=bound, max_x=max_x,
               norm_x=float(np.linalg.norm(truth.x.astype(float))), e0=e0,
               phi_bound=float(np.linalg.norm(obs.Phi, 2)) * e0)
    return out


_TABLES: dict = {}
_RESULTS: dict = {}


def table_for(case: Case, family: str) -> so.GainTable:
    """The case's gain table (designed once per system, family and rate)."""
    system, cycle, _ = SYSTEMS[case.system]
    family = "kalman" if family == "kalman-online" else family     # online: the table's noise model
    key = (case.system, family, case.rate if family == "kalman" else None)
    if key not in _TABLES:
        _TABLES[key] = (so.design_table(system, cycles=[cycle], delta=0.99, progress=False) if family == "lmi"
                        else so.kalman_table(system, [so.design_kalman(system, cycle, case.rate)]))
    return _TABLES[key]


def result(case: Case, family: str) -> dict:
    """:func:`audit` of a case, run once per session (both tests read it)."""
    if (case, family) not in _RESULTS:
        _RESULTS[case, family] = audit(case, family, table_for(case, family))
    return _RESULTS[case, family]


def _params(loose: bool = False) -> list:
    """Every (case, family); with ``loose``, the ones whose bound is known to be uninformative carry
    an xfail (not strict: the run with unix-time stamps settles just within 1e6 of the error on some
    runs, 1.5e8 on others; ``test_bounds_never_below_the_error`` checks all of them hold)."""
    out = []
    for c in CASES:
        for fam in c.families:
            marks = [pytest.mark.slow] if c.slow else []
            if loose and fam == "lmi" and c.system == "unstable15":
                marks.append(pytest.mark.xfail(strict=False, reason=LOOSE_LMI))
            out.append(pytest.param(c, fam, id=f"{c.id}-{fam}", marks=marks))
    return out


#: Why the LMI family's bound on ``unstable15`` is not within six orders of the error (measured: 5.7e5
#: at 17.5 s for an error of 3.7e-3, ||x|| = 2.7e11; an isotropic allowance gives 6.7e46).
LOOSE_LMI = ("channel 2's LMI gain makes ||E|| = 4.65e3 per sample: the rounding of a 2.7e11 state, "
             "u ||x|| = 3e-5 per step, passes through it before the cycle contracts, so the bound settles "
             "at 1.5e8 times the error, above the test's 1e6")


@pytest.mark.parametrize("case,family", _params())
def test_bounds_never_below_the_error(case: Case, family: str):
    """Zero violations: after every update, for every prior and half-way between samples."""
    r = result(case, family)
    if case.system in ("blocks14", "agents10"):     # the paths these cases exist for were taken
        # the anchors verified by the Cholesky check (a warm start stuck in an uncoupled block of
        # S once left two anchors in three to the eigenvalue problem); a candidate more than 5 %
        # above the Rayleigh quotient is not taken (bound_read's proven factor): 1 to 5 anchors in
        # about 90 go to the eigenvalue problem on agents10 (5 with the square-root online recursion)
        assert r["factored"] and r["anchors"] > 0 and r["verified"] >= 0.9 * r["anchors"], r
    assert r["violations"] == 0, f"{r['violations']} of {r['checks']} checks; first: {r['first']}"
    assert r["delta_ratio"] < 1e-3, r          # the truth resolves what is checked (module docstring)
    if case.system in ("unstable15", "blocks14"):
        assert r["max_x"] > 1e11                # the case reached the scale it is named for


@pytest.mark.parametrize("case,family", _params(loose=True))
def test_bounds_say_something(case: Case, family: str):
    """A bound of inf never fails the test above: the final bound must be within six orders of the
    final error, or at the exact-arithmetic bound ``||Phi|| e0`` (noise-free), or at the rounding
    floor ``1e7 u max ||x||`` (a step off the nanosecond grid alone costs ``|dt - dt_q| ||A|| ||x||``,
    up to 1e-9 ||A|| ||x||)."""
    r = result(case, family)
    floor = max(1e6 * r["error"], 1e7 * np.finfo(float).eps / 2 * r["max_x"], 0.0 if case.noise else 2 * r["phi_bound"])
    assert r["bound"] <= floor, {k: v for k, v in r.items() if k != "first"}
