"""A bound on the error of the *computed* estimate that includes floating-point rounding.

The observer's exact bound ``||Phi(t, t0)|| e0`` (e:xtilde_dyn_piecewise) holds in exact
arithmetic. The computed estimate cannot get closer to the true state than rounding allows,
while the contraction makes ``||Phi|| e0`` shrink without limit (0.49x per cycle for the paper's
gains, much faster for Kalman gains), so after a while it falls below the computed error. This
module keeps a bound that stays valid.

Coordinates. Everything below is done in the balanced coordinates ``z = D^{-1} e`` of
:mod:`switchobs_core.numerics.scaling` (``D`` diagonal, powers of two, from ``A``): a map ``M``
is ``D^{-1} M D`` there, a vector ``x`` is ``D^{-1} x``, and every norm named below is taken there
(written ``||.||_D``). The change is exact in floating point, so the ellipsoid is kept in the
user's units (``S`` with ``{e : e' S^-1 e <= 1}``) and the bound is read there, while no residual
or allowance depends on the units of the state: a position in metres beside a velocity in m/s
(``||A||_2 = 3.9e3`` for a 10 Hz oscillator, 65 balanced) gives the same bound as the same
system in balanced units.

Argument (innovation hold or Kalman gains, noise-free samples ``y_k = C x_k``)
------------------------------------------------------------------------------
1. Every step the observer applies is affine in the estimate with matrices it computed:
   ``x_hat_{k+1} = fl(Phi~ x_hat_k + G~ nu_k)`` (LMI: ``nu_k = y_k - C x_hat_k`` held), or
   ``x_hat^- = fl(Phi~ x_hat)``, ``x_hat^+ = fl(x_hat^- + K (y - H x_hat^-))`` (Kalman). The true
   state moves by the exact ``Phi = e^{A dt}`` over the true step ``dt``.
2. Subtracting, the error ``e = x_hat - x`` obeys ``e_{k+1} = M_k e_k + r_k`` with ``M_k`` the step's
   error map of the computed matrices (``Phi~ - G~ C`` or ``(I - K H) Phi~``) and the residual
   ``r_k = (Phi~ - Phi) x_k + delta_k`` (times ``I - K H`` for Kalman), where ``delta_k`` is the
   rounding of the step's arithmetic. The map the ellipsoid is stepped with, ``M~``, is itself
   computed: ``(M - M~) e`` joins the residual with ``||M - M~||_D`` bounded entrywise.
3. ``||Phi~ - Phi||_D <= eps + q``: ``eps`` the matrix exponential's error, *proven* for every
   (key, step) by :func:`~switchobs_core.numerics.expm_bound.certify_zoh` (a certified scaling and
   squaring; a step composed from a cached one adds its Taylor remainder and rounding,
   :meth:`~switchobs_core.numerics.propagation.ZOHCache.step`), and ``q`` the step quantum: the
   propagated step ``dt_q`` differs from the true ``dt`` by ``delta`` and
   ``e^{A dt} - e^{A dt_q} = e^{A dt_q} (e^{A (dt - dt_q)} - I)``, so
   ``q <= (||Phi~||_D + eps) (e^{||A||_D delta} - 1)`` (the map difference itself, not
   ``e^{||A|| dt}``). With ``x_k = x_hat_k - e_k``: ``||(Phi~ - Phi) x_k||_D <= (eps + q)
   (||x_hat_k||_D + ||e_k||_D)``, and ``||e_k||_D <= sqrt(trace_D S_k)`` (:meth:`ErrorEllipsoid.lam_scaled`;
   the loop this closes has gain ``eps + q``, about ``1e-13``).
4. ``delta_k`` follows from the standard model of floating point,
   ``|fl(A x) - A x| <= gamma_m |A| |x|`` with ``gamma_m = m u / (1 - m u)`` and ``u = 2^-53``,
   applied to each product and sum of the step (:func:`gamma`); entrywise bounds are the same in
   any diagonal units, and ``|| |A| |x| ||_D <= ||A||_{F,D} ||x||_D``.
5. With ``||r_k||_D <= rho_k`` the residual lies in the ellipsoid ``E(rho^2 D^2)``, and the set of
   possible errors stays inside ``{e : e' S^-1 e <= 1}`` if
   ``S_{k+1} = (1 + a) M S M' + (1 + 1/a) rho^2 D^2`` for any ``a > 0`` (the outer ellipsoid of a
   sum); ``a = rho / sqrt(trace_D(M S M'))`` aims at the largest axis, and ``S_0 = e0^2 I``. Then
   ``||e_k|| <= sqrt(lambda_max(S_k))``. Without rounding (``rho = 0``) this is exactly ``||Phi|| e0``.
6. ``S`` itself is computed in floating point, exactly symmetric (``(Z + Z') / 2``), and positive
   semidefinite (it dominates a PSD matrix), so ``|S_ij| <= s_i s_j`` with ``s = sqrt(diag S)``. The
   computed ``Z = fl(M S M')`` then has ``|Z - M S M'| <= c w w'`` entrywise with ``w = |M| s`` and
   ``c = gamma_{2n+2}`` (two products and the symmetrisation; a product whose sums have fewer
   terms rounds less: with ``M`` sparse, at most ``k`` nonzeros in a row, both products
   sum at most ``k`` nonzero terms per entry (a term ``0 * x`` and a sum ``s + 0`` are exact), so
   ``|fl(M S) - M S| <= gamma_k |M| |S|``, then ``gamma_k`` again on the computed ``M S``, in all
   ``(2 gamma_k + gamma_k^2) w w' <= gamma_{2k} w w'``: ``c = gamma_{2k}``, about 12 ``u`` for
   ``camera_agents(32)``'s held-innovation map (``k = 6``) against 266 ``u``; the symmetrisation's own rounding is
   counted at the assembly), and for any symmetric ``X`` with
   ``|X| <= c w w'``: ``x' X x <= c (sum_i w_i |x_i|)^2 <= c W sum_i w_i d_i x_i^2`` (Cauchy-Schwarz
   with weights ``w_i / (d_i W)``, ``W = sum_j w_j / d_j``). So ``Z + c W diag(w d)`` contains
   ``M S M'`` in the PSD order: an allowance in the shape of the step's image of the ellipsoid,
   the same in any units, which the next step does not amplify beyond that image (an isotropic
   ``gamma n ||M||_F^2 trace S I`` is amplified by ``||M||^2`` by the next step: 4e6 for a Kalman
   gain in SI units). The scalings and sums of step 5 are rounded too: relative ``u`` entrywise,
   dominated the same way and on the diagonal.

7. Bounded measurement noise ``|v_j| <= v_max`` (``noise_max`` of the observer): the noise
   enters as ``G v`` (LMI: ``G = Gamma_A L``, the held innovation's gain; Kalman: ``G = K``)
   with ``||v||^2 <= p v_max^2``, inside the degenerate ellipsoid ``E(p v_max^2 G G')`` (its rounding
   bounded like step 6 with the row norms of ``G``). The outer ellipsoid of ``E(S1) + E(S2)`` is
   ``E((1 + a) S1 + (1 + 1/a) S2)`` for any ``a > 0`` (``S2`` may be singular; ``a =
   sqrt(trace_D S2 / trace_D S1)`` minimises the trace in balanced units), and the ball of step 5
   joins ``S2`` the same way (:meth:`ErrorEllipsoid.propagate_shaped`). A second ellipsoid kept
   this way bounds the error under any noise in the box: the *noise bound*.

8. Underflow. The model of step 4 holds for normal numbers; a product that underflows errs by up
   to ``eta / 2`` absolutely (``eta = 2^-1074``, the smallest subnormal; sums of subnormals are
   exact). A decaying system reaches that range in the shape matrix first (``S`` holds squared
   errors: a bound of 1e-154 is ``S ~ 1e-308``), so every step adds an absolute allowance too:
   ``(n + 4) n eta (1 + ||M||_inf)`` on the diagonal of ``S`` (each entry of ``fl(M S M')`` off by at
   most ``n eta (1 + ||M||_inf) / 2``, dominated by ``n`` times that on the diagonal) and the
   residuals' ``eta`` terms (:data:`UNDERFLOW`). The bound then never falls below about
   ``n sqrt(eta) = n 2.2e-162``.

Cost: two n x n products per step (like the transition product itself) and O(n^2) for the
allowances, one eigenvalue problem when the bound is read. A sparse error map (from
:data:`~switchobs_core.bounds.kalman_map.SPARSE_MIN_N` states, at most
:data:`~switchobs_core.bounds.kalman_map.SPARSE_MAX_FILL` of nonzeros: chosen by the count of
nonzeros, deterministically) takes step 6's product in compressed rows, O(nnz n), with ``c =
gamma_{2k}`` and ``w = |M| s`` summed over each row's nonzeros
(:func:`~switchobs_core.bounds.rigorous.open_loop_product`); a Kalman sample with a sparse
``e^{A dt}`` takes it in factors, the sparse ``e^{A dt}`` and a rank-``2p`` term, O(nnz n + n^2 p),
with its own ``c`` and ``w`` (:mod:`switchobs_core.bounds.kalman_map`; where the compiled kernel is built, the
whole step in one call, :meth:`ErrorEllipsoid.step_factored`, and an open-loop prior's plan in another,
:meth:`ErrorEllipsoid.pending_open`: sums in index order, which the allowances above cover as any order, since
``gamma_m`` bounds a sum of ``m`` terms in any order and every scalar sum of nonnegative terms is rounded up by
``1 + 2 gamma_{n+2}``), and from 32 states on the
bound is read in O(n^2) between anchors (:mod:`switchobs_core.bounds.read`). A dense map at small n
costs mostly the calls into numpy: :meth:`ErrorEllipsoid.step_dense` takes the same step in about
seventeen of them (the general assembly about forty), the allowance's scalar factors folded into its
coefficients.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from . import dense_kernel
from .extended import expm_extended
from .pending import PendingSet, assembled

try:        # the gufunc behind np.linalg.eigvalsh (same LAPACK call, without its wrapper's 3 us)
    from numpy.linalg._umath_linalg import eigvalsh_lo as _eigvalsh_lo
except ImportError:     # pragma: no cover - another numpy layout: the public function
    _eigvalsh_lo = None

__all__ = ["UNIT_ROUNDOFF", "UNDERFLOW", "NORMAL", "gamma", "expm_extended", "ErrorEllipsoid", "PendingSet",
           "assembled", "largest_eigenvalue", "verify_against_extended"]

#: Unit roundoff of IEEE double precision, ``u = 2^-53``.
UNIT_ROUNDOFF = 2.0**-53
_U = UNIT_ROUNDOFF
#: The smallest subnormal double, ``2^-1074`` (an underflowing product errs by at most half of it: module
#: docstring, step 8), and the smallest normal one, ``2^-1022`` (a product at or above it errs relative ``u``).
UNDERFLOW, NORMAL = 2.0**-1074, 2.0**-1022
#: :func:`_clamp`'s range; step_dense's factors of ``theta`` and of ``c_2`` (the kernel's too, by ``_aux``)
_ALO, _AHI, _KTH, _K2 = 2.0**-40, 1e150, 1.0 + 4.0 * _U, 1.0 + 2.0 * _U


def gamma(m: int) -> float:
    """``gamma_m = m u / (1 - m u)``: the relative error of a length-m dot product (standard model)."""
    mu = m * UNIT_ROUNDOFF
    return mu / (1.0 - mu)


def _abs(M: np.ndarray) -> tuple[np.ndarray, float]:
    """``(|M|, ||M||_inf)``."""
    aM = np.abs(M)
    return aM, float(aM.sum(axis=1).max()) if aM.size else 0.0


def _zfactors(c: float) -> tuple[float, float]:
    """``(c', k_1)`` of a product with ``|Z - M S M'| <= c w w'`` (step 6): ``c' = c + u (1 + c)`` (with the
    symmetrisation's rounding) and ``q``'s factor ``c' (1 + 4u) + 3u (1 + c') (1 + 4u)`` (``_plan``, the kernel)."""
    cz = c + _U * (1.0 + c)
    return cz, cz * (1.0 + 4.0 * _U) + 3.0 * _U * (1.0 + cz) * (1.0 + 4.0 * _U)


def _clamp(a: float) -> float:
    """A coefficient of an outer sum kept in ``[2^-40, 1e150]`` (any ``a > 0`` is valid; from
    ``2^-40`` on, ``fl(1 + a) - 1`` is exact and positive)."""
    return min(max(a, _ALO), _AHI)


class ErrorEllipsoid:
    """``S`` of the module docstring: ``||e|| <= sqrt(lambda_max(S))``, updated per affine step.

    ``ell = ErrorEllipsoid(n, e0, scale=d)`` (``d`` the balancing of
    :func:`~switchobs_core.numerics.scaling.balance`, default no scaling); ``ell.step(M, rho)`` after
    each step with error map ``M`` and a residual ``r`` with ``||D^{-1} r|| <= rho``; ``ell.bound()``
    (an eigenvalue problem) or ``ell.trace_bound()`` (cheap, larger).
    """

    def __init__(self, n: int, e0: float, scale: np.ndarray | None = None):
        self.n = int(n)
        self.d = np.ones(self.n) if scale is None else np.asarray(scale, dtype=float)
        self._d2 = self.d * self.d                  # exact: powers of two
        self._id2 = 1.0 / self._d2
        self._id = 1.0 / self.d
        self.S = (float(e0) ** 2) * np.eye(self.n)
        self.tr = float(np.trace(self.S))           # >= trace S >= lambda_max (S is PSD)
        self._ii = np.arange(self.n)
        self._gsum = 1.0 + 2.0 * gamma(self.n + 2)  # a computed sum of n nonnegative terms, rounded up
        self.c_dense = gamma(2 * self.n + 2)
        self._cz = self.c_dense + _U * (1.0 + self.c_dense)    # with the symmetrisation's rounding
        self._qc: dict = {}                         # id(G) -> the added set of :meth:`_shaped`
        self._kept: tuple | None = None             # (map, S, its product) for one taker (:meth:`keep_product`)
        self._ones = np.ones(self.n)
        self._dr = float((self.d.max() / self.d.min()) ** 2) if self.n else 1.0   # the scaling's spread
        #: The last shape matrix :meth:`step_dense` assembled (exactly symmetric while it is not changed
        #: in place: :meth:`lam_upper` reads it without the symmetrisation, the solver's error from
        #: :attr:`tr`, ``>= ||S||_F`` for a PSD ``S``).
        self.symmetric: np.ndarray | None = None
        self._ls: tuple = (None,)   # (S, tr, lam_scaled(S)) of the kernel's last step
        self._scratch: np.ndarray | None = None     # scratch(): the transpose and tb Q of _apply
        self._qrows = np.stack((self._ones, self._d2, self._ones, self._ones))  # step_dense's q: w d, d^2, |diag Z|, 1
        # step_dense's constant factors (its docstring): W = Wv kW; R_z = kR W (v d); q's coefficients; aux
        kw, cz = self._gsum * (1.0 + 2.0 * _U), self._cz
        self._kf = (1.0 + 8.0 * _U) * (1.0 + 16.0 * _U)
        self._kW = kw * self._gsum * (1.0 + 4.0 * _U)
        self._kR = cz * (1.0 + 4.0 * _U) * kw
        self._k1 = (cz * (1.0 + 4.0 * _U) + 3.0 * _U * (1.0 + cz) * (1.0 + 4.0 * _U)) * kw * self._kf
        self._k3 = 2.0 * _U * self._kf
        self._aux = np.concatenate((self._id2, self._d2, (self._kW, self._kR, self._gsum, self._k1, self._k3,
                                                          self._kf, _ALO, _AHI, _KTH, _K2, UNDERFLOW)))
        # step_factored's: d, 1/d, 1/d^2, d^2 and _plan's factors (gsum, 1 + 4u, a's clamp, theta's, c_2's, eta,
        # 1 + 8u, 2u); (n + 4) n eta of the diagonal's underflow allowance
        self._faux = np.concatenate((self.d, self._id, self._id2, self._d2, (self._gsum, 1.0 + 4.0 * _U, _ALO, _AHI,
                                                                             _KTH, _K2, UNDERFLOW, 1.0 + 8.0 * _U,
                                                                             2.0 * _U)))
        self._c4f = (self.n + 4) * self.n * UNDERFLOW

    # ------------------------------------------------------------------ helpers
    def lam_scaled(self, S: np.ndarray | None = None) -> float:
        """``>= lambda_max(D^-1 S D^-1)``: its trace (``S`` is PSD), O(n)."""
        if S is None and self._ls[0] is self.S:
            return self._ls[2]          # the kernel's, of the set it made (summed in another order)
        S = self.S if S is None else S
        return max(float(S.diagonal().dot(self._id2)), 0.0) * self._gsum

    def image_bound(self, absM: np.ndarray | Callable[[np.ndarray], np.ndarray]) -> np.ndarray:
        """``w >= |M| s`` (``s = sqrt(diag S)``) for ``absM = |M|``, or a function ``x -> |M| x`` (a
        sparse form, summing a row's nonzeros only): step 6's vector."""
        s = np.sqrt(np.maximum(self.S.diagonal(), 0.0))
        return (absM(s) if callable(absM) else absM @ s) * (self._gsum * (1.0 + 2.0 * _U))

    def _diag(self, w: np.ndarray, c: float) -> np.ndarray:
        """``c W (w d)``, ``W = sum_j w_j / d_j``: the diagonal dominating (in the PSD order) a
        symmetric matrix bounded entrywise by ``c w w'`` (step 6), rounded up."""
        W = float(w @ self._id) * self._gsum
        return (c * W) * (w * self.d) * (1.0 + 4.0 * _U)

    def _shaped(self, G: np.ndarray, c: float, GGt: np.ndarray | None) -> tuple:
        """``(Q, R_q, w_q, trace_D(Q + R_q))`` of the added set ``E(c G G')`` (module docstring, step 7):
        ``Q = sym fl(c fl(G G'))``, its allowance ``R_q`` and vector ``w_q``. Kept for the last few
        ``(G, c)`` (a held innovation's ``Gamma L`` and a channel's ``p v_max^2`` recur every cycle),
        ``G`` compared by value: the same doubles as computing them again."""
        hit = self._qc.get(id(G))
        if hit is not None and hit[1] == c and hit[2] is GGt and np.array_equal(hit[0], G):
            return hit[3]
        given = GGt
        if GGt is None:
            GGt = G @ G.T
        Q = c * GGt
        Q += Q.T
        Q *= 0.5
        g = np.sqrt(np.einsum("ij,ij->i", G, G)) * (self._gsum * (1.0 + 2.0 * _U))     # row norms
        cq = gamma(G.shape[1] + 4)          # |fl(c G G') - c G G'| <= cq c g g', symmetrised
        wq = g * math.sqrt(c * (1.0 + cq))
        rq = self._diag(g, cq * c)
        tq = max(float((Q.diagonal() + rq) @ self._id2), 0.0) * self._gsum
        if len(self._qc) >= 64:
            self._qc.clear()
        self._qc[id(G)] = (G.copy(), c, given, (Q, rq, wq, tq))
        return Q, rq, wq, tq

    def scratch(self) -> np.ndarray:
        """A C-ordered n x n array free between steps (:meth:`_apply`'s, in cache after a step): a temporary."""
        if self._scratch is None:
            self._scratch = np.empty((self.n, self.n))
        return self._scratch

    def keep_product(self, key: object, Z: np.ndarray) -> None:
        """Keep ``Z``, a product of the current ``S`` through the map ``key`` (the open-loop step's
        ``Phi~ S Phi~'`` of a prior), for the step at the same time that takes the same product first
        (:meth:`take_product`): the same doubles, computed once. ``Z`` may be a :class:`PendingSet`."""
        if isinstance(Z, PendingSet):
            Z.kept = True
        self._kept = (key, self.S, Z)

    def take_product(self, key: object) -> np.ndarray | None:
        """The product :meth:`keep_product` kept for the map ``key`` (compared by identity) of the
        current ``S`` (the very array it was computed from), handed over once (the taker may overwrite
        it); None otherwise. Anything kept is dropped."""
        k, self._kept = self._kept, None
        if k is None or k[0] is not key or k[1] is not self.S:
            return None
        return k[2].take() if isinstance(k[2], PendingSet) else k[2]

    # ------------------------------------------------------------------ steps
    def propagate(self, M: np.ndarray, rho: float, absM: tuple | None = None) -> tuple[np.ndarray, float]:
        """The next ``(S, trace S)`` for a step ``(M, rho)``, without keeping it; ``absM`` is
        ``(|M|, ||M||_inf)`` if the caller keeps them."""
        Z = M @ self.S @ M.T
        aM, mn = _abs(M) if absM is None else absM
        return self.propagate_product(Z, self.image_bound(aM), self.c_dense, rho, mn)

    def propagate_product(self, Z: np.ndarray, w: np.ndarray, c: float, rho: float,
                          mn: float) -> tuple[np.ndarray, float]:
        """:meth:`propagate` from a product taken elsewhere: ``Z`` (overwritten) with
        ``|Z - M S M'| <= c w w'`` entrywise before its symmetrisation here, up to underflow, and
        ``mn >= ||M||_inf`` (:class:`~switchobs_core.bounds.kalman_map.KalmanMap`'s factored form)."""
        return self._assemble(Z, w, c, rho, None, mn)

    def propagate_shaped(self, M: np.ndarray, rho: float, G: np.ndarray, c: float,
                         GGt: np.ndarray | None = None, absM: tuple | None = None) -> tuple[np.ndarray, float]:
        """The next ``(S, trace S)`` for ``e <- M e + r + G v`` with ``||D^{-1} r|| <= rho`` and
        ``||v||^2 <= c`` (module docstring, step 7): the added set is the degenerate ellipsoid
        ``E(c G G')`` plus the ball, so the noise fills only the directions ``G`` reaches.
        ``GGt`` is ``G G'`` if the caller has it (its float rounding is allowed for)."""
        Z = M @ self.S @ M.T
        aM, mn = _abs(M) if absM is None else absM
        return self._assemble(Z, self.image_bound(aM), self.c_dense, rho, (G, c, GGt), mn)

    def propagate_shaped_product(self, Z: np.ndarray, w: np.ndarray, cz: float, rho: float, mn: float,
                                 G: np.ndarray, c: float, GGt: np.ndarray | None = None) -> tuple[np.ndarray, float]:
        """:meth:`propagate_shaped` from a product taken elsewhere (as :meth:`propagate_product`)."""
        return self._assemble(Z, w, cz, rho, (G, c, GGt), mn)

    def _assemble(self, Z: np.ndarray, w: np.ndarray, cz: float, rho: float,
                  noise: tuple | None, mn: float) -> tuple[np.ndarray, float]:
        """``S' = (1 + a) (Z + R_z) + (1 + 1/a) [(1 + b) (Q + R_q) + (1 + 1/b) rho^2 D^2]`` with the
        allowances of steps 5-7 and the rounding of this assembly (module docstring); ``Z`` overwritten."""
        return self._apply(Z, self._plan(Z.diagonal(), w, cz, rho, noise, mn))

    def pending(self, Z: np.ndarray, w: np.ndarray, cz: float, rho: float, mn: float, G: np.ndarray | None = None,
                c: float = 0.0, remake: Callable[[], np.ndarray] | None = None) -> PendingSet:
        """:meth:`propagate_product` (``G`` None) or :meth:`propagate_shaped_product` whose n x n assembly waits
        for a reader of the whole set (:class:`PendingSet`; its blocks and trace in O(p^2 + n)); ``remake``
        forms ``Z`` again should it be handed over before (:meth:`PendingSet.take`)."""
        return PendingSet(self, Z, self._plan(Z.diagonal(), w, cz, rho, None if G is None else (G, c, None), mn),
                          remake)

    def pending_open(self, Z: np.ndarray, phi: tuple, c: float, rho: float, mn: float,
                     remake: Callable[[], np.ndarray] | None = None) -> PendingSet | None:
        """:meth:`pending` of an open-loop step through a sparse ``Phi~`` (``phi = (indptr, indices, |data|)``,
        ``Z = Phi~ S Phi~'`` with allowance ``c``, ``mn >= ||Phi~||_inf``) planned by the compiled kernel:
        ``w = image_bound(|Phi~|)`` and :meth:`_plan`'s operations with the factors of :attr:`_faux`, its sums in
        index order (rounded up as :meth:`step_factored` says); None where the kernel is not built or refuses."""
        cz, c1f, rho = *_zfactors(c), (rho if rho >= 0.0 else math.inf)    # a NaN rho bounds nothing
        hit = dense_kernel.open_plan(Z, self.S, *phi, self._faux, rho, self._gsum * (1.0 + 2.0 * _U), cz, c1f,
                                     self._c4f, mn)
        if hit is None:
            return None
        q, alpha, theta, trace, tr = hit
        return PendingSet(self, Z, (alpha, theta, None, q, trace, tr), remake)

    def _plan(self, zd: np.ndarray, w: np.ndarray, cz: float, rho: float, noise: tuple | None,
              mn: float) -> tuple:
        """The O(n) part of :meth:`_assemble` from ``zd``, the diagonal of ``Z`` before its symmetrisation:
        ``(alpha, tb, Q, q, trace, tr)`` with ``S' = alpha sym Z (+ tb Q)`` and ``q`` added to its diagonal,
        ``trace`` the sum of that diagonal and ``tr`` it rounded up (the doubles the n x n passes give)."""
        n, d2, id2, rho = self.n, self._d2, self._id2, (rho if rho >= 0.0 else math.inf)   # NaN rho: inf
        zs = zd + zd                # the diagonal of sym Z = (Z + Z') / 2, as the full pass rounds it
        zs *= 0.5
        cz, c1f = _zfactors(cz)         # the symmetrisation's rounding, relative u of |sym Z|; q's factor
        wd = w * self.d
        Wz = float(w @ self._id) * self._gsum
        rz = (cz * Wz * (1.0 + 4.0 * _U)) * wd      # _diag(w, cz): the allowance of step 6
        tz = max(float((zs + rz) @ id2), 0.0) * self._gsum       # trace_D of E(Z + R_z)
        Q, rq, wq, tq = None, None, None, 0.0
        if noise is not None:
            G, c, GGt = noise
            if G.size and c > 0.0:
                Q, rq, wq, tq = self._shaped(G, c, GGt)
                if not tq > 0.0:
                    Q = None
        # the added set: E(Q + R_q) (+) E(rho^2 D^2) inside E(beta (Q + R_q) + kappa rho^2 D^2)
        rho2 = rho * rho
        beta, kappa = 1.0, 1.0
        if Q is not None and rho > 0.0:
            b = _clamp(rho * math.sqrt(n) / math.sqrt(tq))
            beta, kappa = (1.0 + b) * (1.0 + 2.0 * _U), (1.0 + 1.0 / b) * (1.0 + 2.0 * _U)
        tn = beta * tq + kappa * n * rho2            # trace_D of the added set
        # the propagated set and the added one: alpha (Z + R_z) + (1 + 1/a) (added)
        alpha, theta = 1.0, 1.0
        if tz > 0.0 and (tn > 0.0 or rho > 0.0):
            a = _clamp(rho / math.sqrt(tz)) if Q is None else _clamp(math.sqrt(tn) / math.sqrt(tz))
            alpha = 1.0 + a                 # the factor applied; a' = alpha - 1 is its exact pair
            theta = (1.0 + 1.0 / (alpha - 1.0)) * (1.0 + 4.0 * _U)
        sd = zs * alpha if alpha != 1.0 else zs
        # alpha R_z, and the rounding of alpha Z (relative u of |alpha Z| <= alpha (1 + cz) w w',
        # dominated like step 6: 3 u alpha (1 + cz) W diag(w d))
        q = (alpha * c1f * Wz) * wd
        if rho > 0.0:
            q += ((theta * kappa * rho) * rho * (1.0 + 2.0 * _U) + UNDERFLOW) * d2
        tb = theta * beta
        if Q is not None:
            sd = sd + tb * Q.diagonal()
            q += tb * rq
            # the rounding of alpha Z + beta' Q: relative 2u of |alpha Z| + |beta' Q|, entrywise
            q += self._diag(wq, 3.0 * _U * tb)
        # the diagonal's own addition: relative u of the result (and q's few operations); underflow
        # (step 8): the products' absolute errors, and those of c G G' and the scalings
        dS = np.abs(sd)
        dS *= 2.0 * _U
        dS += (n + 4) * n * UNDERFLOW * (2.0 + mn + (0 if noise is None else 1.0))
        q += dS
        q *= 1.0 + 8.0 * _U
        trace = float((sd + q).sum())
        return alpha, tb, Q, q, trace, max(trace, 0.0) * self._gsum

    def _apply(self, Z: np.ndarray, plan: tuple) -> tuple[np.ndarray, float]:
        """The n x n passes of :meth:`_assemble` on ``Z`` (overwritten) with its :meth:`_plan`: ``alpha sym Z``
        as ``(Z + Z') (alpha / 2)``, ``Z'`` copied into :meth:`scratch` (``Z += Z'`` makes a new temporary), the
        halving folded into the scaling: ``fl(fl(x / 2) alpha) = fl(x (alpha / 2))`` where ``x / 2`` is normal,
        below that one rounding instead of two, within the plan's underflow allowance (step 8)."""
        alpha, tb, Q, q, _, tr = plan
        T = self.scratch()
        np.copyto(T, Z.T)
        Z += T                      # exactly symmetric: (Z + Z')_ij = (Z + Z')_ji
        Z *= 0.5 * alpha
        if Q is not None:
            np.multiply(Q, tb, out=T)
            Z += T
        if Z.flags.c_contiguous or Z.flags.f_contiguous:    # the diagonal in place: a strided view
            dS = Z.ravel(order="K")[:: self.n + 1]
            dS += q
        else:
            Z[self._ii, self._ii] += q
        return Z, tr

    def _block(self, Z: np.ndarray, plan: tuple, cols: np.ndarray) -> np.ndarray:
        """``S'[np.ix_(cols, cols)]`` of :meth:`_apply` without the n x n passes (the same doubles; without a shaped
        set by the compiled kernel where it is built, :func:`~switchobs_core.numerics.dense_kernel.block`)."""
        alpha, tb, Q, q, _, _ = plan
        if Q is None and (B := dense_kernel.block(Z, cols, 0.5 * alpha, q)) is not None:
            return B
        ix = cols[:, None], cols
        B = Z[ix]
        B = B + B.T
        B *= 0.5 * alpha
        if Q is not None:
            B += tb * Q[ix]
        B[np.diag_indices(cols.size)] += q[cols]
        return B

    def step_dense(self, M: np.ndarray, absM: tuple, rho: float, guarded: bool = False) -> None:
        """:meth:`step` through a dense ``M``, ``absM = (|M|, ||M||_inf[, D |M|])`` kept by the caller: the set of
        :meth:`propagate_product` (``Z = M S M'``, ``w = image_bound(|M|)``, ``c = gamma_{2n+2}``: step 6) rounded
        in another order, by the compiled kernel where it is built (:mod:`~switchobs_core.numerics.dense_kernel`:
        the same set and allowances), else in numpy. ``w d`` is ``(D |M|) s`` (scalings by powers of two are
        exact); ``w``'s scalar factors fold into the coefficients of ``q = c_1 w d + c_2 d^2 + c_3 |diag Z| + c_4``,
        each rounded up by ``(1 + 16 u)`` more (the fold, the sum of four nonnegative terms); ``(Z + Z') alpha / 2``
        is ``alpha sym Z``; the trace only chooses ``a`` (any ``a > 0`` is valid): from ``diag Z`` and ``w``;
        :attr:`tr` is the new diagonal's sum rounded up. Where ``||M||_inf^2 trace S alpha``, ``theta rho^2`` (times
        ``D``'s spread) stay far below overflow no error state is set up and the kernel may run; elsewhere numpy
        runs under one (``guarded``). A NaN (or negative) ``rho`` bounds nothing: ``rho = inf``, a set not finite.
        Differs from :meth:`propagate_product`'s set within ``2 gamma_{2n+2} alpha |M||S||M'|`` + the diagonal's
        allowance (relative to the diagonal ~1e-13 for a well-conditioned ``M`` and ``S``, not in general)."""
        rho = rho if rho >= 0.0 else math.inf
        if not guarded and not (absM[1] * absM[1] * self.tr * self._dr < 1e250 and rho < 1e120):
            with np.errstate(over="ignore", invalid="ignore"):
                return self.step_dense(M, absM, rho, True)
        aMd = absM[2] if len(absM) > 2 else absM[0] * self.d[:, None]
        c4 = (self.n + 4) * self.n * UNDERFLOW * (2.0 + absM[1]) * self._kf
        hit = None if guarded or dense_kernel.STEP is None else dense_kernel.step(M, self.S, aMd, self._aux, rho, c4)
        if hit is not None and hit[3] < 1e20 and hit[4] * (rho * rho) * self._dr < 1e250:   # the guards below
            self.S, self.tr, self.symmetric, self._ls = hit[0], hit[1], hit[0], hit
            return
        S, B = self.S, self._qrows
        s = np.sqrt(np.abs(S.diagonal()))   # diag S = |diag S| (S is PSD)
        vd = np.dot(aMd, s, out=B[0])       # w d = vd gsum (1 + 2 u)  (image_bound)
        Z = M.dot(S).dot(M.T)
        zd = Z.diagonal()
        Wv = float(vd.dot(self._id2))
        Wz = Wv * self._kW                  # W of step 6, rounded up
        tz = max(float(zd.dot(self._id2)) + self._kR * Wz * Wv, 0.0) * self._gsum     # trace_D (Z + R_z)
        alpha, theta = 1.0, 1.0
        if tz > 0.0 and rho > 0.0:
            alpha = 1.0 + _clamp(rho / math.sqrt(tz))
            theta = (1.0 + 1.0 / (alpha - 1.0)) * _KTH
        if not guarded and not (alpha < 1e20 and theta * (rho * rho) * self._dr < 1e250):     # (the kernel's too)
            with np.errstate(over="ignore", invalid="ignore"):
                return self.step_dense(M, absM, rho, True)
        np.abs(zd, out=B[2])
        c2 = ((theta * rho) * rho * _K2 + UNDERFLOW) * self._kf if rho > 0.0 else 0.0
        q = np.array((alpha * Wz * self._k1, c2, alpha * self._k3, c4)).dot(B)
        # the n x n pass: S' = (Z + Z') (alpha / 2) + diag(q), tr its trace rounded up
        S = Z + Z.T                 # exactly symmetric
        S *= 0.5 * alpha
        dS = S.ravel()[:: self.n + 1]
        dS += q
        self.S, self.tr, self.symmetric = S, max(float(dS.dot(self._ones)), 0.0) * self._gsum, S

    def step_factored(self, Y: np.ndarray, phi: tuple, mn: float, K: np.ndarray, H: tuple, wf: float,
                      c: float, rho: float) -> bool:
        """:meth:`propagate_product` of a Kalman sample's factored map (:meth:`~switchobs_core.bounds.kalman_map.
        KalmanMap.step`) by the compiled kernel, kept: ``Y = Phi~ S Phi~'`` (overwritten with the new ``S``),
        ``phi = (indptr, indices, |data|)`` of ``Phi~``, ``mn`` the map's underflow gain (step 8), ``K`` (n x p),
        ``H = (indptr, indices, data)`` in compressed rows, ``w``'s factor ``wf`` and the product's allowance
        ``c``: the kernel forms ``Z`` and ``w`` as the map's docstring says (steps 1-3) and assembles the set of
        :meth:`_plan` and :meth:`_apply` (steps 5-8) with the factors below and in :attr:`_faux`, every sum in index
        order (the allowances hold for any order: the standard model's ``gamma_m`` bounds a sum of ``m`` terms
        in any order, and each scalar sum of nonnegative terms is rounded up by ``gsum`` whatever its order), so
        the set differs from numpy's in its last bits only; :attr:`tr` and :meth:`lam_scaled` from its diagonal.
        False (nothing changed, ``Y`` intact) where the kernel is not built or refuses the arrays."""
        cz, c1f, rho = *_zfactors(c), (rho if rho >= 0.0 else math.inf)    # a NaN rho bounds nothing
        hit = dense_kernel.factored(Y, self.S, *phi, K, *H, self._faux, rho, wf, cz, c1f, self._c4f, mn)
        if hit is None:
            return False
        self.S, self.tr, self._ls = Y, hit[0], (Y, hit[0], hit[1])
        return True

    def step(self, M: np.ndarray, rho: float, absM: tuple | None = None) -> None:
        """Apply one step: ``e <- M e + r`` with ``||D^{-1} r|| <= rho``."""
        self.S, self.tr = self.propagate(M, rho, absM)

    def step_shaped(self, M: np.ndarray, rho: float, G: np.ndarray, c: float,
                    GGt: np.ndarray | None = None, absM: tuple | None = None) -> None:
        """Apply one noise step (:meth:`propagate_shaped`)."""
        self.S, self.tr = self.propagate_shaped(M, rho, G, c, GGt, absM)

    def trace_bound(self) -> float:
        """``sqrt(trace S) >= ||e||`` (cheap)."""
        return math.sqrt(max(self.tr, 0.0))

    def finite(self) -> bool:
        """Whether ``S`` is finite (a bound that overflowed is not)."""
        return math.isfinite(self.tr)

    def bound(self, S: np.ndarray | None = None) -> float:
        """``sqrt(lambda_max(S)) >= ||e||`` (of ``S``, default the current one), inflated for the
        eigenvalue solver's own error (relative ``n u``); ``inf`` for an ``S`` that is not finite."""
        return math.sqrt(self.lam_upper(S))

    def lam_upper(self, S: np.ndarray | None = None) -> float:
        """``>= lambda_max((S + S') / 2)`` (of ``S``, default the current one): the eigenvalue
        problem's solution plus the solver's own error (relative ``n u``); ``inf`` when ``S`` is
        not finite or the solver does not converge (never raises)."""
        S = self.S if S is None else S
        if not self.n:
            return 0.0
        if S is self.symmetric and S is self.S and self.tr < 1e300:
            nS = self.tr        # exactly symmetric (step_dense) and PSD: ||S||_F <= trace S <= tr
        else:
            S = S + S.T
            S *= 0.5
            nS = fro_norm(S) + math.sqrt(S.size * UNDERFLOW)   # + what underflow hides (frobenius.fro_upper)
            if not math.isfinite(nS):
                return math.inf
        lam = math.nan
        try:
            if _eigvalsh_lo is not None:
                lam = float(_eigvalsh_lo(S, signature="d->d")[-1])
            if not math.isfinite(lam):
                lam = float(np.linalg.eigvalsh(S)[-1])
        except np.linalg.LinAlgError:
            return math.inf
        if not math.isfinite(lam):
            return math.inf
        return max(lam, 0.0) + 2 * self.n * UNIT_ROUNDOFF * nS + 4 * self.n * UNDERFLOW


def largest_eigenvalue(S: np.ndarray) -> float:
    """``np.linalg.eigvalsh(S)[-1]`` (the same LAPACK call and doubles) through its gufunc, without
    the wrapper's checks; where that gives no finite value, the wrapper decides (it raises
    ``LinAlgError`` when the solver does not converge). Under numpy's default error state a
    matrix with a NaN also warns (``invalid value``) before that ``LinAlgError``, and under
    ``errstate(invalid="raise")`` it raises ``FloatingPointError`` instead: callers that may
    pass one run it under ``errstate(all="ignore")`` (the screening does)."""
    if _eigvalsh_lo is not None:
        lam = float(_eigvalsh_lo(S, signature="d->d")[-1])
        if math.isfinite(lam):
            return lam
    return float(np.linalg.eigvalsh(S)[-1])


def fro_norm(X: np.ndarray) -> float:
    """``np.linalg.norm(X)`` (Frobenius) with the same arithmetic (``sqrt`` of the dot product of
    ``X.ravel(order="K")`` with itself), without the wrapper's checks."""
    v = X.ravel(order="K")
    return math.sqrt(float(v.dot(v)))


def verify_against_extended(system, observer, schedule, rate: float, seconds: float, x0,
                            *, every: int = 100, noise_max: float = 0.0, seed: int = 0) -> dict:
    """Run ``observer`` on the outputs of ``system`` and count where its exact bound fails
    against an extended-precision truth (the check of the module docstring's claim).

    The plant starts at ``x0`` and is propagated with :func:`expm_extended` exponentials of the
    true steps ``t_k = k / rate`` (not whole nanoseconds in general); each output is the true
    ``C_rho x`` rounded once to double. With ``noise_max > 0`` every row gets noise at a corner
    of the declared box, ``+-noise_max`` with a seeded random sign (the extreme case), and the
    observer's ``noise_bound`` is checked instead. Returns ``violations``, ``samples``,
    ``worst`` (largest error / bound), ``ratios`` (bound / error every ``every`` samples), and
    the final ``error``, ``bound`` and ``norm_x``.
    """
    x = np.asarray(x0, dtype=np.longdouble)
    C = [np.asarray(Ci, dtype=np.longdouble) for Ci in system.C]
    rng = np.random.default_rng(seed)
    F: dict = {}
    viol, worst, ratios = 0, 0.0, []
    t_prev, err, b = 0.0, 0.0, 0.0
    K = int(round(seconds * rate))
    for k in range(K + 1):
        t = k / rate
        dt = t - t_prev
        if dt > 0:
            key = round(dt * 1e12)
            if key not in F:
                F[key] = expm_extended(system.A, dt)
            x = F[key] @ x
        t_prev = t
        ch = schedule.channel_at(t)
        y = C[ch - 1] @ x
        if noise_max:
            y = y + np.longdouble(noise_max) * rng.choice([-1.0, 1.0], size=y.size)
        xh = observer.update(t, ch, np.asarray(y, dtype=float))
        env = observer.envelope()
        b = env.noise_bound if noise_max else env.exact_bound
        err = float(np.linalg.norm(np.asarray(xh, dtype=np.longdouble) - x))
        viol += err > b
        worst = max(worst, err / b) if b > 0 else (math.inf if err > 0 else worst)
        if k % every == 0:
            ratios.append(b / max(err, 1e-300))
    return {"violations": int(viol), "samples": K + 1, "worst": worst, "ratios": np.array(ratios),
            "error": err, "bound": b, "norm_x": float(np.linalg.norm(np.asarray(x, dtype=float)))}
