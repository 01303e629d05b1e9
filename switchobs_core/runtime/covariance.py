"""The error covariance through one exact step (Joseph-free: the step's error map is exact).

.. math::

    P \\leftarrow E P E' + Q_d(dt) + (\\Gamma L) R (\\Gamma L)'

with ``E`` the step's error map (:mod:`switchobs_core.numerics.propagation`: ``e^{A dt} -
Gamma_A L C`` with a held innovation, e:switched_observer; ``e^{A dt}`` with nothing held),
``Q_d`` the van Loan discretisation of the process intensity ``Q_c``
(:class:`~switchobs_core.design.riccati.DiscretizationCache`) and the last term the held
measurement noise driven through ``Gamma L`` (LMI gains, innovation hold; a Kalman family has
none: its correction follows at the sample). ``E P E'`` is taken in factors when ``E`` is sparse
(:meth:`CovarianceStep.sparse_map`: a held gain changes only the columns its channel reads, so at 32
agents ``E`` has 210 nonzeros of 17 424), each entry summed over a row's nonzeros only, the same
covariance as the dense products up to their rounding. The gain families keep their covariance with it; the
Kalman families keep a factor of it (``P = L L'``, :meth:`CovarianceStep.factor_step`, the
square-root form of :mod:`switchobs_core.runtime.families.online`). A bias test's block of the prior
is taken on the few states a held step maps into itself (:class:`HeldBlock`), and a run of equal
steps waiting to be taken (:class:`PendingSteps`) by powers of ``E`` in compressed rows where they
stay sparse.
"""

from __future__ import annotations

from collections import OrderedDict
from typing import Any

import numpy as np
from scipy.linalg.lapack import dtrcon as _dtrcon

from ..bounds.kalman_map import SparseTransition, sparse_form, sparse_transition
from ..design.riccati import DiscretizationCache
from ..numerics.kalman_step import psd_sqrt, symmetrize
from ..numerics.propagation import DEFAULT_DT_RESOLUTION

__all__ = ["CovarianceStep", "PendingSteps", "HeldBlock", "HeldNoise", "set_entries", "CHOLESKY_RCOND"]

#: Smallest reciprocal condition (LAPACK's 1-norm estimate) of the Cholesky factor of a predicted
#: covariance that :meth:`CovarianceStep.factor_step` keeps (the covariance's condition is its square:
#: about 1e12); below it the exact square root is taken instead.
CHOLESKY_RCOND = 1e-6


class CovarianceStep:
    """``P`` through the observer's steps under a noise model (module docstring).

    ``CovarianceStep(A, B, noise, dt_resolution)``; :meth:`step` is the propagation the family
    keeps, :meth:`prior` the one reported without keeping it.
    """

    def __init__(self, A: np.ndarray, B: np.ndarray, noise: Any, dt_resolution: float | None) -> None:
        self._dcache = DiscretizationCache(A, B, noise.Q_c, dt_resolution=dt_resolution or DEFAULT_DT_RESOLUTION)
        self._qs: dict[int, tuple] = {}       # id(Q_d) -> (Q_d, its square root or None for Q_d = 0)
        self._maps: dict[int, tuple] = {}     # id(e) -> (e, the sparse form of e.E or None)

    def step(self, P: np.ndarray, e: Any, dt: float, held_noise: np.ndarray | None = None) -> np.ndarray:
        """``E P E' + Q_d(dt)`` (+ ``held_noise``) for the ZOH cache entry ``e``, symmetrised; ``E`` in
        factors when it is sparse: a held gain's error map (:meth:`sparse_map`), the open-loop map of a
        Kalman family (:func:`~switchobs_core.bounds.kalman_map.sparse_transition`)."""
        _, _, Q_d = self._dcache.get(dt)
        sp = sparse_transition(e) if e.E is e.Phi else self.sparse_map(e)
        return _added(sp.sandwich(P) if sp is not None else e.E @ P @ e.E.T, Q_d, held_noise)

    def sparse_map(self, e: Any) -> SparseTransition | None:
        """The sparse form of the error map ``E = e^{A dt} - Gamma_A L C`` of an entry ``e`` that holds a
        gain, kept per entry; None when the dense products are the faster (fewer than
        :data:`~switchobs_core.bounds.kalman_map.SPARSE_MIN_N` states or a fill above
        :data:`~switchobs_core.bounds.kalman_map.SPARSE_MAX_FILL`) or when ``e`` holds none (``E`` is
        ``e^{A dt}``: :func:`~switchobs_core.bounds.kalman_map.sparse_transition`)."""
        if e.E is e.Phi:
            return None
        hit = self._maps.get(id(e))
        if hit is None or hit[0] is not e:
            if len(self._maps) >= 4 * self._dcache.maxsize:
                self._maps.clear()
            hit = self._maps[id(e)] = (e, sparse_form(e.E))
        return hit[1]

    def factor_step(self, L: np.ndarray, e: Any, dt: float) -> np.ndarray:
        """:meth:`step` in square-root form, for a Kalman family (nothing held): from a factor ``L`` of
        ``P`` (``P = L L'``) a factor of ``P^- = E P E' + Q_d(dt)``.

        The Cholesky factor of ``P^-`` formed from ``E L`` when it is well conditioned (LAPACK's
        estimate of its reciprocal condition at least :data:`CHOLESKY_RCOND`: ``P^-``'s condition
        within about 1e12, the range :mod:`switchobs_core.design.precision` accepts, with four
        digits or more in its smallest direction), an n x n triangle; otherwise the
        exact square root ``[E L, Q_d^{1/2}]`` (n x 2n, as
        :func:`~switchobs_core.numerics.kalman_step.sqrt_predict`), which the next correction's QR
        compresses, with ``Q_d^{1/2}`` kept with its cached ``Q_d`` (none for ``Q_d = 0``). ``E L``
        is taken in factors when ``e^{A dt}`` is sparse."""
        _, _, Q_d = self._dcache.get(dt)
        sp = sparse_transition(e) if e.E is e.Phi else None
        EL = np.asarray(sp.csr @ L) if sp is not None else e.E @ L
        try:
            C = np.linalg.cholesky(EL @ EL.T + Q_d)
            if float(_dtrcon(C, norm="1", uplo="L")[0]) >= CHOLESKY_RCOND:
                return C
        except np.linalg.LinAlgError:
            pass
        hit = self._qs.get(id(Q_d))
        if hit is None or hit[0] is not Q_d:
            if len(self._qs) >= 2 * self._dcache.maxsize:
                self._qs.clear()
            hit = self._qs[id(Q_d)] = (Q_d, psd_sqrt(Q_d) if np.any(Q_d) else None)
        return EL if hit[1] is None else np.hstack([EL, hit[1]])

    def q_d(self, dt: float) -> np.ndarray:
        """``Q_d(dt)`` (the cached array: the same object for the same quantised step)."""
        return self._dcache.get(dt)[2]

    def prior_is_step(self, e: Any) -> bool:
        """Whether :meth:`prior` and :meth:`step` through ``e`` are the same arithmetic (``e`` holds a
        gain: both take :meth:`sparse_map`'s form or both the dense products; nothing held: both dense),
        hence the same numbers."""
        return e.E is not e.Phi or sparse_transition(e) is None

    def prior(self, P: np.ndarray, e: Any, dt: float, held_noise: np.ndarray | None = None) -> np.ndarray:
        """The same (the prior a consistency test reads), with dense products where nothing is held."""
        _, _, Q_d = self._dcache.get(dt)
        sp = self.sparse_map(e)
        return _added(sp.sandwich(P) if sp is not None else e.E @ P @ e.E.T, Q_d, held_noise)


    def prior_block(self, P: np.ndarray, e: Any, dt: float, cols: np.ndarray, *, factor: bool = False) -> np.ndarray:
        """:meth:`prior` ``(P, e, dt)`` (nothing held) on the rows and columns ``cols`` only:
        ``E_r P_K E_r' + Q_d[cols, cols]`` with ``E_r = E[cols, K]``, ``K`` the columns where
        ``E[cols]`` has a nonzero (exact zeros add nothing), ``P_K = P[K, K]``, or from a factor
        (``factor``: ``P = L L'``, ``P_K = L[K] L[K]'``): O(|cols| n + |K|^2 m) instead of three
        n x n products. The same block as :meth:`prior`'s up to rounding (sums of the same nonzero
        products in another order: ``test_prior_block.py``)."""
        _, _, Q_d = self._dcache.get(dt)
        Er = e.E[cols]
        K = np.flatnonzero(np.any(Er != 0, axis=0))
        Ek = Er[:, K]
        PK = symmetrize(P[K] @ P[K].T) if factor else P[np.ix_(K, K)]
        return symmetrize(Ek @ PK @ Ek.T + Q_d[np.ix_(cols, cols)])


class PendingSteps:
    """The steps of :meth:`CovarianceStep.step` taken when the covariance is read, not at every sample.

    ``push(e, dt, R)`` records a step (``R`` the held measurement noise, driven through the entry's
    ``Gamma L``; None: nothing held) in O(1): a step equal to the previous one (the same cached ZOH
    entry, ``Q_d`` and ``R``: a residence at a fixed rate) lengthens its run. ``apply(P)`` takes
    the runs in order: a run of one or a few steps by :meth:`CovarianceStep.step` itself (the same
    arithmetic as at every sample), a run of ``m >= MIN_DOUBLING`` steps by binary powers,
    ``P <- E^{2^i} P E^{2^i}' + S_i`` for each bit ``i`` of ``m``, with ``S_0 = Q``,
    ``S_{i+1} = E^{2^i} S_i E^{2^i}' + S_i`` and ``Q = Q_d + Gamma L R (Gamma L)'``: about
    ``2 log2 m`` products of n x n matrices instead of ``2 m`` (in compressed rows where a power is
    sparse: a held gain's at 32 agents stays within one agent and the common states; the powers are
    kept per step, up to :data:`POWER_BYTES`), the same covariance up to rounding. :meth:`push` returns True when
    :data:`MAX_RUNS` runs wait (the caller applies them: the work is then what it was).
    """

    #: Runs kept before :meth:`push` asks for them to be applied.
    MAX_RUNS = 64
    #: Shortest run taken by powers.
    MIN_DOUBLING = 4
    #: Bytes of powers kept (least recently used dropped first).
    POWER_BYTES = 64 << 20

    def __init__(self, cov: CovarianceStep) -> None:
        self._cov = cov
        self._runs: list[list] = []             # [e, dt, Q_d, R, count]
        self._held = HeldNoise()
        self._powers: OrderedDict = OrderedDict()   # (id(e), id(Q_d), id(R)) -> (e, Q_d, R, [(E^2^i, S_i, its CSR)])
        self._bytes = 0

    def __len__(self) -> int:
        return len(self._runs)

    def clear(self) -> None:
        self._runs.clear()

    def push(self, e: Any, dt: float, R: np.ndarray | None) -> bool:
        Q_d = self._cov.q_d(dt)
        last = self._runs[-1] if self._runs else None
        if last is not None and last[0] is e and last[2] is Q_d and last[3] is R:
            last[4] += 1
            return False
        self._runs.append([e, dt, Q_d, R, 1])
        return len(self._runs) > self.MAX_RUNS

    def apply(self, P: np.ndarray) -> np.ndarray:
        """``P`` through every pending step (then none is pending)."""
        for e, dt, Q_d, R, m in self._runs:
            if m < self.MIN_DOUBLING:
                held = None if R is None else self._held(e, R)
                for _ in range(m):
                    P = self._cov.step(P, e, dt, held)
                continue
            levels = self._levels(e, Q_d, R, m.bit_length())
            for i in range(m.bit_length()):
                if m >> i & 1:
                    Ei, Si, spi = levels[i]
                    P = symmetrize((spi.sandwich(P) if spi is not None else Ei @ P @ Ei.T) + Si)
        self._runs.clear()
        return P

    def _levels(self, e: Any, Q_d: np.ndarray, R: np.ndarray | None, k: int) -> list:
        """``[(E^{2^i}, S_i)]`` for ``i < k`` (class docstring), kept."""
        key = (id(e), id(Q_d), id(R))
        hit = self._powers.get(key)
        if hit is None or hit[0] is not e or hit[1] is not Q_d or hit[2] is not R:
            if hit is not None:
                self._drop(key)
            Q = Q_d if R is None else Q_d + e.GL @ R @ e.GL.T
            hit = (e, Q_d, R, [(e.E, symmetrize(Q), sparse_form(e.E))])
            self._powers[key] = hit
            self._bytes += 2 * Q.nbytes
        self._powers.move_to_end(key)
        levels = hit[3]
        while len(levels) < k:
            Ei, Si, spi = levels[-1]
            E2 = Ei @ Ei if spi is None else np.asarray(spi.csr @ Ei)
            levels.append((E2, symmetrize((Ei @ Si @ Ei.T if spi is None else spi.sandwich(Si)) + Si), sparse_form(E2)))
            self._bytes += 2 * Si.nbytes
        while self._bytes > self.POWER_BYTES and len(self._powers) > 1:
            self._drop(next(iter(self._powers)))
        return levels

    def _drop(self, key: Any) -> None:
        _, _, _, levels = self._powers.pop(key)
        self._bytes -= sum(E.nbytes + S.nbytes for E, S, _ in levels)


def _added(X: np.ndarray, Q_d: np.ndarray, held_noise: np.ndarray | None) -> np.ndarray:
    """``symmetrize((X + Q_d) + held_noise)``, the sums taken in ``X`` (a product made for this call,
    overwritten): the same elementwise operations as new arrays, hence the same doubles."""
    X += Q_d
    if held_noise is not None:
        X += held_noise
    P = X + X.T
    P *= 0.5
    return P


class HeldNoise:
    """``held(e, R)``: ``(Gamma L) R (Gamma L)'``, the noise a held sample adds over the step of the
    ZOH entry ``e`` (its held gain ``Gamma L``, the held sample's noise covariance ``R``), kept per
    entry and ``R`` (the objects, by identity; the last 256 entries)."""

    def __init__(self) -> None:
        self._kept: dict = {}

    def __call__(self, e: Any, R: np.ndarray) -> np.ndarray:
        hit = self._kept.get(id(e))
        if hit is None or hit[0] is not e or hit[1] is not R:
            if len(self._kept) >= 256:
                self._kept.clear()
            hit = self._kept[id(e)] = (e, R, e.GL @ R @ e.GL.T)
        return hit[2]


class HeldBlock:
    """The covariance's block ``P[K, K]`` on a set ``K`` of states that each step maps into itself,
    carried step by step while the full covariance waits (:class:`PendingSteps`).

    The prior's block on ``cols`` (a bias test's rows) is ``E[cols, K] P[K, K] E[cols, K]' +
    Q_d[cols, cols] + H[cols, cols]`` (``H = (Gamma L) R (Gamma L)'`` the held sample's noise,
    module docstring) with ``K`` the columns where ``E[cols]`` has a nonzero (exact zeros add
    nothing). :meth:`closure` takes the smallest ``K`` holding ``cols`` with ``E[K]`` zero outside
    ``K``: a held gain at 32 agents reads one agent and the common states, ``|K| = 8`` of 132.
    While the steps keep that property (a residence on one channel), :meth:`step` carries
    ``B = P[K, K]`` through each, ``E[K, K] B E[K, K]' + Q_d[K, K] + H[K, K]`` (the full step's
    block, summed over the same nonzero products: equal up to rounding, ``test_held_block.py``),
    so a sample costs no n x n product; a step that leaves ``K`` drops it (:attr:`K` None), and
    the owner starts it again from the full covariance (:meth:`start`).
    """

    #: Largest share of the states a block is kept for (beyond it the full products are as cheap).
    MAX_SHARE = 0.25

    def __init__(self, cov: CovarianceStep) -> None:
        self._cov = cov
        self.K: np.ndarray | None = None
        self.B: np.ndarray | None = None
        self._sets: dict = {}     # (id(e), cols) -> (e, K or None, np.ix_ of cols' positions in K)
        self._maps: dict = {}     # (id(e), K) -> [e, E[K, K] or None (E[K] leaves K), Q_d, R, Q_d + H on K]
        self._next: tuple | None = None     # (e, Q_d, R, B through e): the last prior

    def clear(self) -> None:
        self.K = self.B = self._next = None

    def closure(self, e: Any, cols: np.ndarray) -> tuple[np.ndarray, tuple] | None:
        """``(K, the index of the cols block within K's)`` for the step ``e`` (class docstring), or None when ``K``
        holds more than :data:`MAX_SHARE` of the states; kept per step and ``cols``."""
        key = (id(e), cols.tobytes())
        hit = self._sets.get(key)
        if hit is None or hit[0] is not e:
            if len(self._sets) >= 1024:
                self._sets.clear()
            nz = e.E != 0
            K = np.unique(cols)
            while True:
                grown = np.union1d(K, np.flatnonzero(np.any(nz[K], axis=0)))
                if grown.size == K.size:
                    break
                K = grown
            ok = K.size <= self.MAX_SHARE * nz.shape[0]
            at = np.searchsorted(K, cols)
            hit = self._sets[key] = (e, K if ok else None, np.ix_(at, at) if ok else None)
        return None if hit[1] is None else (hit[1], hit[2])

    def start(self, P: np.ndarray, K: np.ndarray) -> None:
        """Keep ``P[K, K]`` (``P`` the full covariance after the last step)."""
        self.K, self.B, self._next = K, P[np.ix_(K, K)], None

    def holds(self, K: np.ndarray) -> bool:
        """Whether the block kept is on ``K``."""
        return self.K is K or (self.K is not None and np.array_equal(self.K, K))

    def prior(self, e: Any, dt: float, R: np.ndarray | None) -> np.ndarray | None:
        """``B`` through the step ``e`` over ``dt`` with ``R`` held (None: nothing held), kept for
        :meth:`step`; None when ``E[K]`` leaves ``K``."""
        Q_d = self._cov.q_d(dt)
        m = self._map(e, Q_d, R)
        if m[1] is None:
            return None
        EK = m[1]
        B = symmetrize(EK @ self.B @ EK.T + m[4])
        self._next = (e, Q_d, R, B)
        return B

    def step(self, e: Any, dt: float, R: np.ndarray | None) -> None:
        """The owner took the step ``e`` over ``dt`` with ``R`` held: carry ``B`` through it (the
        last :meth:`prior` when it is this step's), or drop it when ``E[K]`` leaves ``K``."""
        if self.K is None:
            return
        nxt, self._next = self._next, None
        if nxt is not None and nxt[0] is e and nxt[1] is self._cov.q_d(dt) and nxt[2] is R:
            self.B = nxt[3]
            return
        B = self.prior(e, dt, R)
        self._next = None
        if B is None:
            self.clear()
        else:
            self.B = B

    def _map(self, e: Any, Q_d: np.ndarray, R: np.ndarray | None) -> list:
        K = self.K
        key = (id(e), K.tobytes())
        hit = self._maps.get(key)
        if hit is None or hit[0] is not e:
            if len(self._maps) >= 1024:
                self._maps.clear()
            rows = e.E[K]
            inside = not np.any(np.delete(rows, K, axis=1))
            hit = self._maps[key] = [e, rows[:, K] if inside else None, None, None, None]
        if hit[1] is not None and (hit[2] is not Q_d or hit[3] is not R):
            QH = Q_d[np.ix_(K, K)]
            if R is not None:
                G = e.GL[K]
                QH = QH + G @ R @ G.T
            hit[2:] = [Q_d, R, QH]
        return hit


def set_entries(P: np.ndarray, indices: Any, variances: dict) -> np.ndarray:
    """A copy of ``P`` with row and column ``i`` zeroed and ``P[i, i] = variances[i]`` (default
    the previous ``P[i, i]``) for every ``i`` in ``indices``: the set entries' errors are then
    uncorrelated with the others (:meth:`~switchobs_core.runtime.observer.SwitchedObserver.set_estimate`)."""
    P = P.copy()
    for i in indices:
        var = float(variances.get(i, P[i, i]))
        P[i, :] = 0.0
        P[:, i] = 0.0
        P[i, i] = var
    return P
