"""The simulated plant (e:system): ``xdot = A x + B u + w``, advanced exactly between
sample times by matrix exponentials, with seeded process noise of the exact discretised
covariance. Used by the offline simulation and by the ROS camera simulator.

Equation labels (``e:...``) are those of the paper and resolve in ``docs/equations.md``.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ..exceptions import InvalidArgument
from ..numerics.propagation import van_loan, zoh_pair
from ..numerics.rounding import expm_extended

__all__ = ["Plant"]


def input_at(u: Any, t: float, m: int) -> np.ndarray | None:
    """The input at ``t``: ``u`` itself or ``u(t)`` for a callable, as an ``m``-vector (None for None)."""
    if u is None:
        return None
    val = u(t) if callable(u) else u
    val = np.asarray(val, dtype=float).reshape(-1)
    if val.size != m:
        raise InvalidArgument(f"u must have m = {m} entries; got {val.size}")
    return val


class Plant:
    """Exact plant ``xdot = A x + B u + w`` (e:system) with seeded noise.

    ``plant = Plant(system, x0, seed=0, process_noise=0.0)``

    Parameters
    ----------
    system : LTISystem
    x0 : (n,) array_like, optional
        Initial state (zeros if None).
    seed : int
        Seed of the noise generator (numpy ``default_rng``).
    process_noise : float or (n, n) array_like
        Spectral density of the white process noise ``w``: a scalar ``q`` means
        ``Qc = q**2 I``; a matrix is ``Qc`` itself. 0 (default) for none.
    t0 : float
        Initial time.
    extended : bool
        Keep the state in extended precision (``np.longdouble``, exponentials by
        :func:`~switchobs_core.numerics.rounding.expm_extended`): the reference against which the
        rounding-aware bounds are checked (``simulate`` uses it; about 10x slower per step).
        :attr:`x` is then the state rounded once to double, :attr:`x_extended` the state.
    B_w : (n, q) array_like, optional
        The matrix of a bounded unknown input ``w`` (:mod:`switchobs_core.model.disturbance`):
        ``xdot = A x + B u + B_w w``, ``w`` given to :meth:`advance` and held over the step.

    Notes
    -----
    :meth:`advance` is exact: ``x <- e^{A dt} x + Gamma B u + w_d`` with ``w_d`` drawn
    from the exact discretised covariance ``Qd = int_0^dt e^{As} Qc e^{A's} ds``
    (Van Loan), ``u`` (and ``w``) held over the step: ``Gamma B u + Gamma B_w w`` from one
    augmented exponential ``e^{[[A, B, B_w], [0, 0, 0]] dt}``.
    """

    def __init__(self, system: Any, x0: Any = None, seed: int = 0,
                 process_noise: Any = 0.0, *, t0: float = 0.0, extended: bool = False, B_w: Any = None):
        self.A = np.asarray(system.A, dtype=float)
        self.n = self.A.shape[0]
        B = np.asarray(system.B, dtype=float)
        B = B.reshape(self.n, -1) if B.size else np.zeros((self.n, 0))
        self.m = B.shape[1]
        Bw = np.zeros((self.n, 0)) if B_w is None else np.asarray(B_w, dtype=float).reshape(self.n, -1)
        self.q = Bw.shape[1]
        self.B = B
        self._BB = np.hstack([B, Bw]) if self.q else B      # [B, B_w]: one ZOH for the known and the unknown input
        self.C = tuple(np.asarray(Ci, dtype=float) for Ci in system.C)
        self._x = np.zeros(self.n) if x0 is None else np.array(x0, dtype=float).reshape(-1)
        if self._x.size != self.n or not np.isfinite(self._x).all():
            raise InvalidArgument(f"x0 must hold n = {self.n} finite entries; got {self._x.size}")
        self._t = float(t0)
        if not math.isfinite(self._t):
            raise InvalidArgument(f"t0 must be finite; got {t0!r}")
        self.rng = np.random.default_rng(seed)
        Qc = np.asarray(process_noise, dtype=float)
        if Qc.ndim == 0:
            if not (math.isfinite(float(Qc)) and Qc >= 0):
                raise InvalidArgument(f"process_noise must be >= 0; got {process_noise}")
            Qc = float(Qc) ** 2 * np.eye(self.n)
        elif Qc.shape != (self.n, self.n) or not np.isfinite(Qc).all():
            raise InvalidArgument(f"process_noise must be a scalar or an ({self.n}, {self.n}) matrix")
        self.Qc = Qc
        self._noisy = bool(np.any(Qc))
        self._steps: dict = {}
        self.extended = bool(extended)
        if self.extended:
            self._xl = np.asarray(self._x, dtype=np.longdouble)
            self._Cl = tuple(np.asarray(Ci, dtype=np.longdouble) for Ci in self.C)

    @property
    def x(self) -> np.ndarray:
        """Current state (a copy)."""
        return self._x.copy()

    @property
    def x_extended(self) -> np.ndarray:
        """Current state in extended precision (a copy; ``extended=True`` only)."""
        if not self.extended:
            raise InvalidArgument("x_extended needs Plant(..., extended=True)")
        return self._xl.copy()

    @property
    def t(self) -> float:
        """Current time."""
        return self._t

    def _step(self, dt: float):
        s = self._steps.get(dt)
        if s is None:
            if self.extended:       # [[F, Gamma B], [0, I]] = e^{[[A, B], [0, 0]] dt}, extended
                n, m = self.n, self._BB.shape[1]
                J = np.zeros((n + m, n + m))
                J[:n, :n], J[:n, n:] = self.A, self._BB
                X = expm_extended(J, dt)
                F, GB = X[:n, :n], X[:n, n:]
            else:
                F, G = zoh_pair(self.A, dt)
                GB = G @ self._BB
            Lq = None
            if self._noisy:
                _, Qd = van_loan(self.A, self.Qc, dt)
                w, V = np.linalg.eigh(Qd)
                Lq = V * np.sqrt(np.clip(w, 0, None))
            s = self._steps[dt] = (F, GB, Lq)
            if len(self._steps) > 256:
                self._steps.pop(next(iter(self._steps)))
        return s

    def advance(self, t: float, u: Any = None, w: Any = None) -> np.ndarray:
        """Advance exactly to ``t`` with ``u`` (and the unknown input ``w``, ``B_w``) held over
        ``[plant.t, t]``; returns ``x(t)``."""
        dt = float(t) - self._t
        if not dt >= 0 or not math.isfinite(dt):
            raise InvalidArgument(f"t = {t!r} must be a finite time >= the plant's time {self._t!r}")
        if dt > 0:
            F, GB, Lq = self._step(dt)
            x = F @ (self._xl if self.extended else self._x)
            if u is not None:
                u = np.asarray(u, dtype=float).reshape(-1)
                if u.size != self.m:
                    raise InvalidArgument(f"u must have m = {self.m} entries; got {u.size}")
                x += GB[:, :self.m] @ u
            if w is not None:
                w = np.asarray(w, dtype=float).reshape(-1)
                if w.size != self.q:
                    raise InvalidArgument(f"w must have q = {self.q} entries (the columns of B_w); got {w.size}")
                x += GB[:, self.m:] @ w
            if Lq is not None:
                x += Lq @ self.rng.standard_normal(self.n)
            if self.extended:
                self._xl = x
                x = np.asarray(x, dtype=float)
            self._x = x
        self._t = float(t)
        return self._x.copy()

    def measure(self, channel: int, noise_std: float = 0.0, rows: Any = None,
                noise_max: float | None = None) -> np.ndarray:
        """``y = C_channel x + v`` with ``v ~ N(0, noise_std^2 I)`` (channel 1-based), each row
        clipped to ``[-noise_max, noise_max]`` when ``noise_max`` is given (bounded noise).
        With ``extended`` the product is taken in extended precision and rounded once."""
        if not (isinstance(channel, (int, np.integer)) and 1 <= channel <= len(self.C)):
            raise InvalidArgument(f"channel must be an integer in 1..{len(self.C)}; got {channel!r}")
        Ci = (self._Cl if self.extended else self.C)[channel - 1]
        if rows is not None:
            Ci = Ci[list(rows), :]
        y = np.asarray(Ci @ self._xl, dtype=float) if self.extended else Ci @ self._x
        if noise_std:
            if not (math.isfinite(noise_std) and noise_std > 0):
                raise InvalidArgument(f"noise_std must be >= 0; got {noise_std}")
            v = noise_std * self.rng.standard_normal(y.size)
            if noise_max is not None:
                v = np.clip(v, -noise_max, noise_max)
            y = y + v
        return y
