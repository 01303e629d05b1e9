"""Exact zero-order-hold propagation by augmented matrix exponentials (Section 4).

Between two samples the switched observer (e:switched_observer) is the linear
system with constant forcing

.. math::

    \\dot{\\hat x} = M \\hat x + w, \\qquad M = A - L_i C_i, \\qquad w = B u + L_i y,

where ``y`` and ``u`` are held (zero-order hold) since the last sample. Its exact
solution over a step ``dt`` is ``x(t + dt) = Phi x(t) + Gamma w`` with

.. math::

    \\begin{bmatrix} \\Phi & \\Gamma \\\\ 0 & I \\end{bmatrix}
    = \\exp\\left(\\begin{bmatrix} M & I \\\\ 0 & 0 \\end{bmatrix} dt\\right),
    \\qquad \\Phi = e^{M dt}, \\quad \\Gamma = \\int_0^{dt} e^{M s}\\, ds .

Innovation hold (the default of the observer). Holding the *measurement* makes the
sampled error depend on the plant's own motion (the held y lags a moving plant), which on
a plant with unstable modes lets the error grow with the state. Holding the *innovation*
``nu_k = y_k - C_i x_hat(t_k)`` instead,

.. math::

    \\dot{\\hat x} = A \\hat x + B u + L_i \\nu_k, \\qquad
    \\hat x(t_k + dt) = e^{A dt} \\hat x(t_k) + \\Gamma_A (B u + L_i \\nu_k),

gives the error map ``E = e^{A dt} - Gamma_A L_i C_i`` per step: exact, independent of
the plant state, and equal to ``e^{(A - L_i C_i) dt}`` up to O(dt^2). For such a key the
cache entry holds ``Phi = e^{A dt}``, ``GL = Gamma_A L``, ``GB = Gamma_A B`` and ``E``; for a
measurement-hold key ``E = Phi = e^{(A - L C) dt}`` (the error map of continuous outputs).

No ODE solver and no tolerance is involved. :class:`ZOHCache` keeps ``(Phi, Gamma)``
(and the products ``Gamma L`` and ``Gamma B``) per (gain key, quantised ``dt``) in a
small LRU, so a repeated step costs three matrix-vector products.

Time quantisation. ``dt`` is rounded to a multiple of ``dt_resolution`` (default
1 ns, the resolution of ROS stamps) before the lookup, and the step that is
propagated is exactly the rounded one. Without this, float jitter in ``t_k - t_{k-1}``
(about 1e-16 s) would make every step at a fixed rate a cache miss. The discrepancy
is at most ``dt_resolution / 2`` per step; pass ``dt_resolution=None`` for no rounding.

Paper labels (``e:...``, ``t:...``) resolve to numbers in ``docs/equations.md``.
"""

from __future__ import annotations

import math
from collections import OrderedDict
from collections.abc import Hashable

import numpy as np
from scipy.linalg import expm

from ..exceptions import InvalidArgument
from ..validation import as_matrix
from .expm_bound import certify_zoh, expm_error_bound, nu
from .frobenius import fro_upper
from .rounding import UNIT_ROUNDOFF, gamma

__all__ = [
    "zoh_pair",
    "transition",
    "van_loan",
    "ZOHEntry",
    "ZOHCache",
    "DEFAULT_DT_RESOLUTION",
    "quantize_dt",
]

#: Default step quantum in seconds (ROS stamps are integer nanoseconds).
DEFAULT_DT_RESOLUTION = 1e-9

#: Grid of the composed steps: a step ``dt`` that misses the cache is ``e^{M a} e^{M r}`` with ``a``
#: on this grid (cached; a sensor's jittered periods fall on a few grid points) and the remainder
#: ``r < COMPOSE_GRID`` by a degree-:data:`COMPOSE_DEGREE` Taylor sum whose truncation and
#: rounding enter the entry's ``eps`` (:meth:`ZOHCache.step`). Measured: 296 -> see bench/RESULTS.md.
COMPOSE_GRID = 1e-4
COMPOSE_DEGREE = 6
#: Exponentials kept for keys of the same ``M`` (:meth:`ZOHCache._exact`).
SHARED_KEPT = 8


def quantize_dt(dt: float, resolution: float | None) -> float:
    """Round ``dt`` to a multiple of ``resolution`` (no rounding if ``resolution`` is None)."""
    dt = _check_dt(dt)
    if resolution is None:
        return dt
    if not (isinstance(resolution, (int, float, np.floating)) and math.isfinite(resolution) and resolution > 0):
        raise InvalidArgument(f"resolution must be a finite number > 0 or None; got {resolution!r}")
    return round(dt / resolution) * resolution


def _check_dt(dt: float, name: str = "dt") -> float:
    """``dt`` as a finite float >= 0, or InvalidArgument naming it."""
    try:
        val = float(dt)
    except (TypeError, ValueError):
        raise InvalidArgument(f"{name} must be a number; got {dt!r}") from None
    if not (math.isfinite(val) and val >= 0):
        raise InvalidArgument(f"{name} must be a finite step >= 0 (seconds); got {val}")
    return val


def transition(M: np.ndarray, dt: float) -> np.ndarray:
    """State transition ``Phi = expm(M dt)`` of ``xdot = M x``."""
    M = as_matrix(M, "M", square=True)
    return expm(M * _check_dt(dt))


def zoh_pair(M: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """Exact ZOH discretisation ``(Phi, Gamma)`` of ``xdot = M x + w``, ``w`` constant.

    ``[[Phi, Gamma], [0, I]] = expm([[M, I], [0, 0]] dt)``, so that
    ``x(t + dt) = Phi x(t) + Gamma w``.

    Parameters
    ----------
    M : (n, n) array_like
        System matrix, e.g. ``A - L_i C_i`` of (e:xtilde_dyn_piecewise).
    dt : float
        Step length in seconds (>= 0).

    Returns
    -------
    Phi, Gamma : (n, n) ndarray
        ``Phi = e^{M dt}`` and ``Gamma = int_0^dt e^{M s} ds``.
    """
    M = as_matrix(M, "M", square=True)
    n = M.shape[0]
    aug = np.zeros((2 * n, 2 * n))
    aug[:n, :n] = M
    aug[:n, n:] = np.eye(n)
    E = expm(aug * _check_dt(dt))
    return np.ascontiguousarray(E[:n, :n]), np.ascontiguousarray(E[:n, n:])


def van_loan(A: np.ndarray, Qc: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """Exact discretisation of ``xdot = A x + w``, ``E[w w'] = Qc delta`` (Van Loan).

    Returns ``(F, Qd)`` with ``F = e^{A dt}`` and
    ``Qd = int_0^dt e^{A s} Qc e^{A' s} ds`` from
    ``expm([[-A, Qc], [0, A']] dt) = [[., F^{-1} Qd], [0, F']]``.
    """
    A = as_matrix(A, "A", square=True)
    n = A.shape[0]
    Qc = as_matrix(Qc, "Qc", rows=n, cols=n)
    aug = np.zeros((2 * n, 2 * n))
    aug[:n, :n] = -A
    aug[:n, n:] = Qc
    aug[n:, n:] = A.T
    E = expm(aug * _check_dt(dt))
    F = E[n:, n:].T
    Qd = F @ E[:n, n:]
    Qd = 0.5 * (Qd + Qd.T)
    return F, Qd


class ZOHEntry:
    """One cached step: ``Phi``, ``Gamma``, the input products ``GL = Gamma L``, ``GB = Gamma B``,
    and the error map ``E`` of the step (module docstring), with what the rigorous bound reads
    of them in the balanced coordinates of ``scale`` (:mod:`switchobs_core.numerics.scaling`; a
    matrix ``X`` there is ``D^{-1} X D``, a gain ``D^{-1} G``):

    ``eps``, ``epsG``
        proven bounds of ``||Phi - e^{M dt}||_2`` and ``||Gamma - Gamma(dt)||_2`` there
        (:mod:`switchobs_core.numerics.expm_bound`);
    ``fPhi``, ``nPhi``, ``fGL``, ``fGB``
        ``||Phi||_F``, a bound of ``||Phi||_2``, ``||GL||_F``, ``||GB||_F`` there;
    ``emap``
        a bound of ``||E - (Phi - GL C)||_2`` there: the rounding of the stored error map
        against the exact one of the computed matrices (0 when ``E`` is ``Phi``).
    """

    __slots__ = ("Phi", "Gamma", "GL", "GB", "E", "dt", "eps", "epsG", "fPhi", "nPhi", "fGL", "fGB", "emap",
                 "scale", "sparse", "sparse_E", "_absE")

    def __init__(self, Phi, Gamma, GL, GB, dt, E=None, eps=0.0, *, epsG=0.0, scale=None, C=None):
        n = Phi.shape[0]
        d = np.ones(n) if scale is None else scale
        self.scale = d
        self.eps = eps           # bound on ||Phi - e^{M dt}||_2, balanced (expm_bound)
        self.epsG = epsG
        Ps = scaled(Phi, d)
        self.fPhi = fro_upper(Ps)
        self.nPhi = nu(Ps)
        self.fGL = 0.0 if GL is None else fro_upper(GL / d[:, None])
        self.fGB = 0.0 if GB is None else fro_upper(GB / d[:, None])
        self.Phi = Phi
        self.Gamma = Gamma
        self.GL = GL
        self.GB = GB
        self.dt = dt
        self.E = Phi if E is None else E
        self.emap = 0.0
        if E is not None and C is not None and GL is not None:
            # E = fl(Phi - fl(GL C)): gamma_p |GL| |C| + u |E| entrywise
            self.emap = (gamma(GL.shape[1] + 1) * nu(GL / d[:, None]) * nu(C * d[None, :])
                         + 2.0 * UNIT_ROUNDOFF * nu(scaled(E, d))) * (1.0 + 8.0 * UNIT_ROUNDOFF)
        self.sparse = False      # Phi's sparse form, None if dense (kalman_map.sparse_transition)
        self.sparse_E = False    # E's sparse form, None if dense (kalman_map.sparse_map)
        self._absE = None

    def abs_E(self) -> tuple[np.ndarray, float]:
        """``(|E|, ||E||_inf)`` (kept: the rigorous bound's step reads them every sample)."""
        if self._absE is None:
            aE = np.abs(self.E)
            self._absE = (aE, float(aE.sum(axis=1).max()) if aE.size else 0.0)
        return self._absE


def scaled(X: np.ndarray, d: np.ndarray) -> np.ndarray:
    """``D^{-1} X D`` (exact for powers of two)."""
    return (X / d[:, None]) * d[None, :]


def split_step(dtq: float, dt_resolution: float | None) -> tuple[int, float]:
    """``dtq = qc COMPOSE_GRID + r`` with ``0 <= r < COMPOSE_GRID``, counted in whole quanta of
    ``dt_resolution`` when there is one (no float residue decides the grid point)."""
    if dt_resolution:
        g = round(COMPOSE_GRID / dt_resolution)
        if g >= 1 and abs(g * dt_resolution - COMPOSE_GRID) < 1e-3 * COMPOSE_GRID:
            qc, rq = divmod(round(dtq / dt_resolution), g)
            return qc, rq * dt_resolution
    qc = int(dtq // COMPOSE_GRID)
    return qc, max(dtq - qc * COMPOSE_GRID, 0.0)


def taylor_pair(M: np.ndarray, r: float, m: int = COMPOSE_DEGREE) -> tuple[np.ndarray, np.ndarray]:
    """``(sum_{k<=m} (M r)^k / k!, r sum_{k<=m} (M r)^k / (k+1)!)``: ``e^{M r}`` and ``Gamma(r)``
    for a short step ``r`` (the composed steps of :class:`ZOHCache` and of
    :class:`~switchobs_core.design.riccati.DiscretizationCache`; the truncation is bounded there).

    The terms ``T_k = T_{k-1} (M r) / k`` are summed in order, ``((I + T_1) + T_2) + ...``, and
    ``Gamma``'s ``I + T_1 / 2 + T_2 / 3 + ...`` likewise (the arithmetic of the term-by-term loop,
    with the terms stacked so that each sum is one reduction). The last result is kept: the
    observer's step and the covariance's Van Loan step of one sample ask for the same pair
    (``M = A``, the same remainder ``r``). The arrays returned are read-only.
    """
    global _taylor_last
    key = (r, m, M.shape, M.tobytes())
    last = _taylor_last
    if last is not None and last[0] == key:
        return last[1], last[2]
    n = M.shape[0]
    T = np.empty((m + 1, n, n))
    T[0] = 0.0
    T[0].flat[:: n + 1] = 1.0
    if m >= 1:
        X = np.multiply(M, r, out=T[1])      # T_1 = I (M r) / 1 = M r exactly (M r is finite)
        for k in range(2, m + 1):
            np.matmul(T[k - 1], X, out=T[k])
            T[k] /= k
    div = _TAYLOR_DIV.get(m)
    if div is None:
        div = _TAYLOR_DIV[m] = np.arange(1.0, m + 2.0).reshape(-1, 1, 1)
    Ps = np.add.reduce(T, axis=0)           # over the outer axis: term by term, in order
    Gs = np.add.reduce(T / div, axis=0)
    Gs *= r
    Ps.flags.writeable = False
    Gs.flags.writeable = False
    _taylor_last = (key, Ps, Gs)
    return Ps, Gs


_TAYLOR_DIV: dict = {}
_taylor_last: tuple | None = None


class ZOHCache:
    """LRU cache of exact ZOH steps keyed by (gain key, quantised dt).

    Parameters
    ----------
    maxsize : int, optional
        Number of entries kept (least recently used evicted first). Default 64.
    dt_resolution : float or None, optional
        Step quantum in seconds (see the module docstring). Default 1e-9.
    scale : (n,) ndarray, optional
        The balancing (:func:`~switchobs_core.numerics.scaling.balance`) in which each entry's
        bounds are taken (default: none, the user's units).

    Notes
    -----
    A gain is registered once with :meth:`register` (``key -> (M, L, B)``); a step is
    then obtained with :meth:`step`. The counters ``hits`` and ``misses`` are public.
    """

    def __init__(self, maxsize: int = 64, dt_resolution: float | None = DEFAULT_DT_RESOLUTION,
                 scale: np.ndarray | None = None):
        if int(maxsize) < 1:
            raise InvalidArgument(f"maxsize must be >= 1; got {maxsize}")
        if dt_resolution is not None and not dt_resolution > 0:
            raise InvalidArgument(f"dt_resolution must be > 0 or None; got {dt_resolution}")
        self.maxsize = int(maxsize)
        self.dt_resolution = dt_resolution
        self._inv_res = None if dt_resolution is None else 1.0 / dt_resolution
        self._gains: dict[Hashable, tuple] = {}
        self._scale = None if scale is None else np.asarray(scale, dtype=float)
        self._consts: dict = {}
        self._lru: OrderedDict = OrderedDict()
        self._shared: dict = {}     # (M's bytes, step, what is formed) -> (Phi, Gamma, eps, epsG): see _exact
        self.hits = 0
        self.misses = 0

    def register(self, key: Hashable, M: np.ndarray, L: np.ndarray | None = None,
                 B: np.ndarray | None = None, *, C: np.ndarray | None = None) -> None:
        """Register ``xdot = M x + L v + B u`` under ``key`` (idempotent).

        With ``C`` given, the key is an innovation-hold key: ``M`` must be ``A`` itself, ``v``
        is the held innovation and the entry's error map is ``E = e^{A dt} - Gamma_A L C``.
        """
        if key not in self._gains:
            M = as_matrix(M, "M", square=True)
            n = M.shape[0]
            L = None if L is None else as_matrix(L, "L", rows=n)
            B = None if B is None or np.size(B) == 0 else as_matrix(B, "B", rows=n)
            if C is not None:
                C = as_matrix(C, "C", cols=n, rows=None if L is None else L.shape[1])
            self._gains[key] = (np.ascontiguousarray(M), L, B, C)

    def has(self, key: Hashable) -> bool:
        """Whether ``key`` has been registered."""
        return key in self._gains

    def step(self, key: Hashable, dt: float) -> ZOHEntry:
        """Return the cached :class:`ZOHEntry` of ``key`` for step ``dt`` (computed on a miss).

        Raises InvalidArgument for a key that was never registered or a ``dt`` that is not a
        finite number >= 0.
        """
        if not 0 <= dt < math.inf:
            dt = _check_dt(dt)
        q = dt if self._inv_res is None else round(dt * self._inv_res)
        lk = (key, q)
        lru = self._lru
        entry = lru.get(lk)
        if entry is not None:
            self.hits += 1
            lru.move_to_end(lk)
            return entry
        self.misses += 1
        try:
            M, L, B, C = self._gains[key]
        except KeyError:
            raise InvalidArgument(f"key {key!r} was never registered (call register first)") from None
        dtq = dt if self._inv_res is None else q * self.dt_resolution
        qc, r = self._split(q, dtq)
        if qc > 0 and r > 0:
            entry = self._compose(self._base(key, qc), M, L, B, C, r, dtq)
        else:
            entry = self._exact(key, M, L, B, C, dtq)
        lru[lk] = entry
        while len(lru) > self.maxsize:
            lru.popitem(last=False)
        return entry

    def _split(self, q, dtq: float) -> tuple[int, float]:
        return split_step(dtq, self.dt_resolution)

    def _base(self, key: Hashable, qc: int) -> ZOHEntry:
        """The exact step of ``key`` over ``qc`` grid units (cached with the other entries)."""
        lk = (key, "grid", qc)
        entry = self._lru.get(lk)
        if entry is None:
            M, L, B, C = self._gains[key]
            entry = self._lru[lk] = self._exact(key, M, L, B, C, qc * COMPOSE_GRID)
            while len(self._lru) > self.maxsize:
                self._lru.popitem(last=False)
        else:
            self._lru.move_to_end(lk)
        return entry

    def _compose(self, base: ZOHEntry, M, L, B, C, r: float, dtq: float) -> ZOHEntry:
        """``e^{M dtq} = e^{M a} e^{M r}`` (``a = dtq - r`` the base's step), ``Gamma(dtq) = e^{M a}
        Gamma(r) + Gamma(a)``, with ``e^{M r} = sum_k (M r)^k / k!`` and ``Gamma(r) = r sum_k (M r)^k /
        (k+1)!`` to degree ``m``. The entry's ``eps`` bounds ``||Phi - e^{M dtq}||_2`` in balanced
        coordinates (every norm here is taken there): the base's own ``eps``, the Taylor tail
        ``x^{m+1}/(m+1)! / (1 - x/(m+2))`` (``x = ||M||_F r``), the sum's rounding ``gamma_{m(n+2)+2}
        (sqrt(n) + e^x)`` and the product's ``gamma_{n+1} ||.||_F ||.||_F``; ``epsG`` likewise for
        ``Gamma`` (the base's ``epsG``, ``r`` times the Taylor sum's tail and rounding)."""
        n = M.shape[0]
        m = COMPOSE_DEGREE
        Ps, Gs = taylor_pair(M, r)
        d = base.scale
        consts = self._consts.get(id(M))
        if consts is None or consts[0] is not M:     # ||M||_F and the gammas, per registered M
            consts = self._consts[id(M)] = (M, fro_upper(scaled(M, d)), math.factorial(m + 1), gamma(m * (n + 2) + 4),
                                            gamma(n + 1), gamma(4))
        _, nM, fact, g_sum, g_n1, g_4 = consts
        x = nM * r
        tail = x ** (m + 1) / fact / (1.0 - x / (m + 2))
        rnd = g_sum * (math.sqrt(n) + math.exp(x))
        nPs, nPb = fro_upper(scaled(Ps, d)), base.fPhi
        Phi = base.Phi @ Ps
        # (a + r) is dtq up to the rounding of the two floats: that step difference, too
        split = abs(base.dt + r - dtq) + 2 * math.ulp(dtq)
        eps = (base.eps * (nPs + tail + rnd) + nPb * (tail + rnd) + g_n1 * nPb * nPs
               + split * nM * nPb * nPs * math.exp(nM * split)) * (1 + g_4)
        Gamma = epsG = None
        if base.Gamma is not None:
            Gamma = base.Phi @ Gs + base.Gamma
            nGs, nGb = fro_upper(scaled(Gs, d)), fro_upper(scaled(base.Gamma, d))
            eg = r * (tail + rnd)
            epsG = (base.eps * (nGs + eg) + nPb * eg + base.epsG + g_n1 * (nPb * nGs + nGb)
                    + split * (nPb + base.eps) * (nPs + tail + rnd) * math.exp(nM * split)) * (1 + g_4)
        GL = None if L is None else Gamma @ L
        E = None if C is None or GL is None else Phi - GL @ C
        return ZOHEntry(Phi, Gamma, GL, None if B is None else Gamma @ B, dtq, E, eps,
                        epsG=0.0 if epsG is None else epsG, scale=d, C=C)

    def _exact(self, key: Hashable, M, L, B, C, dtq: float) -> ZOHEntry:
        """The step over ``dtq`` by ``scipy.linalg.expm`` (the joint pair for a gain key), its error
        proven per (key, step) by :func:`~switchobs_core.numerics.expm_bound.certify_zoh` in balanced
        coordinates (``Gamma``'s too when an input is registered).

        Keys whose ``M`` has the same values (innovation-hold keys: ``M = A`` for every channel) share
        the exponential and its certificate, computed once per step: each entry gets its own copies of
        the same doubles (:data:`SHARED_KEPT` kept, by ``M``'s bytes)."""
        d = self._scale_for(M.shape[0])
        sk = (M.shape, M.tobytes(), dtq, L is None and B is None, B is not None)
        hit = self._shared.get(sk)
        if hit is None:
            if L is None and B is None:      # open loop, no input: Phi alone (half the expm size)
                Phi, Gamma = expm(M * dtq), None
            else:
                Phi, Gamma = zoh_pair(M, dtq)
            cert = certify_zoh(scaled(M, d), dtq, gamma_too=B is not None and Gamma is not None)
            eps = expm_error_bound(scaled(Phi, d), cert.E, cert.dE)
            epsG = expm_error_bound(scaled(Gamma, d), cert.G, cert.dG) if cert.G is not None else 0.0
            if len(self._shared) >= SHARED_KEPT:
                self._shared.clear()
            self._shared[sk] = (Phi.copy(), None if Gamma is None else Gamma.copy(), eps, epsG)
        else:
            Phi, Gamma, eps, epsG = hit
            Phi, Gamma = Phi.copy(), None if Gamma is None else Gamma.copy()
        GL = None if L is None else Gamma @ L
        E = None if C is None or GL is None else Phi - GL @ C
        return ZOHEntry(Phi, Gamma, GL, None if B is None else Gamma @ B, dtq, E, eps, epsG=epsG, scale=d, C=C)

    def _scale_for(self, n: int) -> np.ndarray:
        """The balancing the entries' bounds are taken in (ones when none was given)."""
        if self._scale is None or self._scale.shape[0] != n:
            return np.ones(n)
        return self._scale

    def clear(self) -> None:
        """Drop every cached step (registered gains are kept)."""
        self._lru.clear()
        self._shared.clear()
        self.hits = 0
        self.misses = 0

    def __len__(self) -> int:
        return len(self._lru)
