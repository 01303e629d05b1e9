"""The plant in extended precision: the truth of the bound audits (test_audit.py, _units_audit.py).

``np.longdouble`` on x86-64 (the x87 80-bit format, unit roundoff 5.4e-20). The state is propagated
over an interval ``dt`` (a longdouble: the exact difference of two stamps) in ``m`` equal substeps
``hs = dt / m``, ``m`` the fewest with ``||A hs||_inf <= 1/4``, each the Taylor polynomial of
``exp(A hs)`` of degree ``J``, evaluated by Horner's rule. ``J`` is the least degree whose remainder
``rho^(J+1) / ((J+1)! (1 - rho))`` (``rho = ||A hs||_inf``) is below a 32nd of the unit roundoff
relative to the state: a proven truncation bound, independent of the library's exponentials.

The truth is propagated twice, with ``m`` and ``m + 1`` substeps; their distance ``delta`` (the
truth's own rounding and truncation) is what the audits compare with the bound and add to the error.

Stamps on a grid give only a handful of distinct intervals (the difference of two rounded ``k /
rate`` takes 8-18 values over 15 000-60 000 samples): an interval met a second time has its
transition matrix (the same polynomial applied to the identity) formed once and kept, and each
later step is one longdouble product with it. Jittered stamps, all intervals new, propagate the
vector itself. Either way the same polynomial of ``A hs`` is applied: the two paths differ only in
the order of the longdouble roundings.
"""

from __future__ import annotations

import math

import numpy as np

from switchobs_core.numerics.scaling import balance, balanced

LD = np.longdouble
_TINY = float(np.finfo(LD).eps) / 32


def _degree(rho: float) -> int:
    """The least Taylor degree with the remainder bound of the module docstring below ``_TINY``."""
    if rho <= 0.0:
        return 1
    J, term = 0, rho                 # term = rho^(J+1) / (J+1)!
    while term / (1.0 - rho) > _TINY:
        J += 1
        term *= rho / (J + 1)
    return max(J, 1)


class Truth:
    """The plant ``x' = A x`` in extended precision (module docstring), in the balanced coordinates
    of ``A`` (a power-of-two diagonal similarity, exact) with ``balanced_coordinates``."""

    def __init__(self, A: np.ndarray, x0: np.ndarray, *, balanced_coordinates: bool = False):
        A = np.asarray(A, dtype=float)
        self.d = balance(A) if balanced_coordinates else np.ones(A.shape[0])
        Ab = balanced(A, self.d) if balanced_coordinates else A
        self.A = np.asarray(Ab, dtype=LD)
        self._norm = float(np.abs(Ab).sum(axis=1).max())            # ||A||_inf
        self.h = 0.25 / max(self._norm, 1e-12)
        z0 = np.asarray(x0, dtype=LD) / np.asarray(self.d, dtype=LD)
        self.z = [z0, z0.copy()]
        self._dl = np.asarray(self.d, dtype=LD)
        self._seen: set = set()
        self._maps: dict = {}

    def _substeps(self, dt: LD, extra: int) -> tuple[int, LD, int]:
        m = max(1, math.ceil(float(dt) / self.h)) + extra
        hs = dt / LD(m)
        return m, hs, _degree(self._norm * float(hs))

    def _taylor(self, z: np.ndarray, dt: LD, extra: int = 0) -> np.ndarray:
        """``z`` (a vector, or the identity for the transition matrix) propagated over ``dt``."""
        m, hs, J = self._substeps(dt, extra)
        M = self.A * hs
        for _ in range(m):
            out = z
            for j in range(J, 0, -1):
                out = z + (M @ out) / LD(j)
            z = out
        return z

    def _step(self, z: np.ndarray, dt: LD, extra: int) -> np.ndarray:
        key = (dt, extra)
        if key in self._maps:
            return self._maps[key] @ z
        if key in self._seen:
            self._maps[key] = Phi = self._taylor(np.eye(len(z), dtype=LD), dt, extra)
            return Phi @ z
        self._seen.add(key)
        return self._taylor(z, dt, extra)

    def advance(self, dt: LD) -> None:
        """Propagate both copies over ``dt`` (a longdouble: the exact difference of two stamps)."""
        if dt > 0:
            self.z = [self._step(self.z[0], dt, 0), self._step(self.z[1], dt, 1)]

    def at(self, dt: LD) -> np.ndarray:
        """The state ``dt`` after the current time (original coordinates), without moving."""
        return (self._taylor(self.z[0], dt) if dt > 0 else self.z[0]) * self._dl

    @property
    def x(self) -> np.ndarray:
        """The state in the original coordinates."""
        return self.z[0] * self._dl

    @property
    def delta(self) -> float:
        """The distance of the two copies (original coordinates): the truth's own error."""
        return float(np.linalg.norm(((self.z[0] - self.z[1]) * self._dl).astype(float)))
