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
