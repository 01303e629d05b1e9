"""Small test systems shared by several core test files."""

from __future__ import annotations

import numpy as np

import switchobs_core as so


def oscillators(zeta: tuple[float, float] = (0.01, 0.01), hz: tuple[float, float] = (0.5, 0.8)) -> so.LTISystem:
    """Two oscillators (``hz``, default 0.5 Hz and 0.8 Hz) coupled by a spring of stiffness 1; damping
    ratios ``zeta`` (negative: unstable). Row 0 of both channels is the shared ``q1 + q2``."""
    w1, w2, kc = 2 * np.pi * hz[0], 2 * np.pi * hz[1], 1.0
    A = np.array([[0.0, 1.0, 0.0, 0.0],
                  [-(w1 * w1 + kc), -2 * zeta[0] * w1, kc, 0.0],
                  [0.0, 0.0, 0.0, 1.0],
                  [kc, 0.0, -(w2 * w2 + kc), -2 * zeta[1] * w2]])
    C1 = np.array([[1.0, 0.0, 1.0, 0.0], [1.0, 0.0, 0.0, 0.0]])
    C2 = np.array([[1.0, 0.0, 1.0, 0.0], [0.0, 0.0, 1.0, 0.0]])
    return so.LTISystem(A, None, [C1, C2], name=f"oscillators_{zeta[0]:g}_{zeta[1]:g}_{hz[0]:g}_{hz[1]:g}")


def stiff_pair() -> tuple[so.LTISystem, so.NoiseModel]:
    """Fast stable modes (-200/s, -50/s) beside slow unstable ones, two channels, 1 um noise: Kalman
    covariances whose condition reaches 1.6e14 (test_online_sqrt.py, bench/bench_precision.py)."""
    A = np.diag([-200.0, -50.0, 0.3, 0.1, 0.0, -1.0])
    A[4, 5], A[0, 2], A[2, 3] = 1.0, 5.0, 0.5
    C1 = np.zeros((2, 6))
    C1[0, 0], C1[1, 2], C1[1, 4] = 1.0, 1.0, 0.5
    C2 = np.zeros((2, 6))
    C2[0, 1], C2[1, 3], C2[0, 4], C2[1, 5] = 1.0, 1.0, 1.0, 0.2
    system = so.LTISystem(A, None, [C1, C2], name="stiff")
    return system, so.NoiseModel.for_system(system, measurement_std=1e-6, process_std=0.3)


# ---------------------------------------------------------------------------------------------
# Systems of the bound audit across units, stiffness and channel counts (test/core/bounds/test_units_audit.py,
# bench/bench_units.py): each with its cycle, rate and a true initial state.

def oscillator_si(hz: float = 10.0, zeta: float = 0.005) -> so.LTISystem:
    """A ``hz`` oscillator in SI units (position in m, velocity in m/s: ``||A||_2 = omega^2 = 3.9e3``
    at 10 Hz) driving a second one with the same frequency: ``A = [[A_o, I], [0, A_o]]``, a Jordan
    block of the complex pair. Channel 1 measures the first position, channel 2 the second."""
    w = 2 * np.pi * hz
    Ao = np.array([[0.0, 1.0], [-w * w, -2 * zeta * w]])
    A = np.block([[Ao, np.eye(2)], [np.zeros((2, 2)), Ao]])
    return so.LTISystem(A, None, [np.array([[1.0, 0.0, 0.0, 0.0]]), np.array([[0.0, 0.0, 1.0, 0.0]])],
                        name=f"oscillator_si_{hz:g}hz")


def wide_units(span: float = 3.0, seed: int = 0) -> so.LTISystem:
    """A dense 4-state system (modes -0.05, -0.03, -0.5 +- 2i) in units that differ by ``10^span``
    from one state to the next: entries of A from about ``10^-2span`` to ``10^2span`` (1e-6..1e6
    for ``span = 3``). Channel 1 measures state 0, channel 2 state 1."""
    L = np.array([[-0.05, 0, 0, 0], [0, -0.03, 0, 0], [0, 0, -0.5, 2.0], [0, 0, -2.0, -0.5]])
    V = np.random.default_rng(seed).standard_normal((4, 4))
    B = V @ L @ np.linalg.inv(V)
    T = np.logspace(-span, span, 4)
    A = (T[:, None] * B) / T[None, :]
    return so.LTISystem(A, None, [np.eye(4)[[0]] / T, np.eye(4)[[1]] / T], name=f"wide_units_{span:g}")


def in_units(system: so.LTISystem, T: np.ndarray) -> so.LTISystem:
    """``system`` with state ``i`` in units ``T_i`` times smaller: ``x' = T x``, ``A' = T A T^-1``,
    ``C' = C T^-1`` (the same dynamics in other units)."""
    T = np.asarray(T, dtype=float)
    A = (T[:, None] * np.asarray(system.A)) / T[None, :]
    return so.LTISystem(A, None, [np.asarray(Ci) / T[None, :] for Ci in system.C], name=f"{system.name}_units")


def dense40(seed: int = 2) -> so.LTISystem:
    """n = 40, dense: 20 lightly damped modes (0.1-1 /s, 0.5-5 rad/s) in an orthogonal random basis;
    channel 1 measures states 0-4, channel 2 states 5-9."""
    rng = np.random.default_rng(seed)
    blocks = []
    for s, w in zip(np.linspace(0.1, 1.0, 20), np.linspace(0.5, 5.0, 20)):
        blocks.append(np.array([[-s, w], [-w, -s]]))
    L = np.zeros((40, 40))
    for k, b in enumerate(blocks):
        L[2 * k:2 * k + 2, 2 * k:2 * k + 2] = b
    Q, _ = np.linalg.qr(rng.standard_normal((40, 40)))
    return so.LTISystem(Q @ L @ Q.T, None, [np.eye(40)[0:5], np.eye(40)[5:10]], name="dense40")


def sparse40() -> so.LTISystem:
    """n = 40, sparse: ten uncoupled copies of two coupled oscillators (``oscillators()``, each copy
    0.1 Hz faster); channel 1 measures rows ``q1 + q2`` and ``q1`` of every copy, channel 2
    ``q1 + q2`` and ``q2``."""
    A = np.zeros((40, 40))
    C1, C2 = np.zeros((20, 40)), np.zeros((20, 40))
    for j in range(10):
        o = oscillators(hz=(0.5 + 0.1 * j, 0.8 + 0.1 * j))
        A[4 * j:4 * j + 4, 4 * j:4 * j + 4] = o.A
        C1[2 * j:2 * j + 2, 4 * j:4 * j + 4] = o.C[0]
        C2[2 * j:2 * j + 2, 4 * j:4 * j + 4] = o.C[1]
    return so.LTISystem(A, None, [C1, C2], name="sparse40")


def chain(masses: int, hz: float = 1.0, zeta: float = 0.02) -> so.LTISystem:
    """``masses`` unit masses in a line, each on a spring to ground (``hz``) and coupled to its
    neighbours (stiffness 1); channel ``i`` measures the position of mass ``i``."""
    w2 = (2 * np.pi * hz) ** 2
    K = np.diag(np.full(masses, w2 + 2.0)) - np.diag(np.ones(masses - 1), 1) - np.diag(np.ones(masses - 1), -1)
    n = 2 * masses
    A = np.zeros((n, n))
    A[0::2, 1::2] = np.eye(masses)
    A[1::2, 0::2] = -K
    A[1::2, 1::2] = -2 * zeta * np.sqrt(w2) * np.eye(masses)
    return so.LTISystem(A, None, [np.eye(n)[[2 * i]] for i in range(masses)], name=f"chain{masses}")
