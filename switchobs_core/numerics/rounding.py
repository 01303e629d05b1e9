"""A bound on the error of the *computed* estimate that includes floating-point rounding.

The observer's exact bound ``||Phi(t, t0)|| e0`` (e:xtilde_dyn_piecewise) holds in exact
arithmetic. The computed estimate cannot get closer to the true state than rounding allows,
while the contraction makes ``||Phi|| e0`` shrink without limit (0.49x per cycle for the paper's
gains, much faster for Kalman gains), so after a while it falls below the computed error. This
module keeps a bound that stays valid.

Argument (innovation hold or Kalman gains, noise-free samples ``y_k = C x_k``)
------------------------------------------------------------------------------
1. Every step the observer applies is affine in the estimate with matrices it computed:
   ``x_hat_{k+1} = fl(Phi~ x_hat_k + G~ nu_k)`` (LMI: ``nu_k = y_k - C x_hat_k`` held), or
   ``x_hat^- = fl(Phi~ x_hat)``, ``x_hat^+ = fl(x_hat^- + K (y - H x_hat^-))`` (Kalman). The true
   state moves by the exact ``Phi = e^{A dt}`` over the true step ``dt``.
2. Subtracting, the error ``e = x_hat - x`` obeys ``e_{k+1} = M_k e_k + r_k`` with ``M_k`` the step's
   error map built from the computed matrices (``Phi~ - G~ C`` or ``(I - K H) Phi~``; it is what
   the observer multiplies into ``Phi``) and the residual
   ``r_k = (Phi~ - Phi) x_k + delta_k`` (times ``I - K H`` for Kalman), where ``delta_k`` is the
   rounding of the step's arithmetic.
3. ``||Phi~ - Phi|| <= eps_Phi`` (:func:`expm_error`: the matrix exponential's own error, from a
   model checked against an extended-precision recomputation, plus the step quantum's
   ``|dt - dt_q| ||A|| e^{||A|| dt}``), and ``||x_k|| <= ||x_hat_k|| + ||e_k||``.
4. ``||delta_k||`` follows from the standard model of floating point,
   ``|fl(A x) - A x| <= gamma_m |A| |x|`` with ``gamma_m = m u / (1 - m u)`` and ``u = 2^-53``,
   applied to each product and sum of the step (:func:`gamma`; the absolute matrices' Frobenius
   norms bound ``|| |A| |x| ||``).
5. With ``||r_k|| <= rho_k``, the set of possible errors stays inside the ellipsoid
   ``{e : e' S^-1 e <= 1}`` if ``S_{k+1} = (1 + a) M S M' + (1 + 1/a) rho^2 I`` for any ``a > 0``
   (the outer ellipsoid of the sum of an ellipsoid and a ball); ``a = rho / sqrt(lambda_max(M S M'))``
   is the best choice for the largest axis, and ``S_0 = e0^2 I``. Then
   ``||e_k|| <= sqrt(lambda_max(S_k))``. Without rounding (``rho = 0``) this is exactly
   ``||Phi|| e0``.
6. ``S`` itself is computed in floating point: each step adds ``eta I`` with
   ``eta = gamma_{2n+2} n ||M||_F^2 ||S||_F`` (and the same allowance for the ball term), which
   dominates the rounding of ``M S M'`` elementwise, so the computed ``S`` stays an upper bound
   in the PSD order.

7. Bounded measurement noise ``|v_j| <= v_max`` (``noise_max`` of the observer): the noise
   enters as ``G v`` (LMI: ``G = Gamma_A L``, the held innovation's gain; Kalman: ``G = K``)
   with ``||v||^2 <= p v_max^2``, inside the degenerate ellipsoid ``E(p v_max^2 G G')``. The
   outer ellipsoid of ``E(S1) + E(S2)`` is ``E((1 + a) S1 + (1 + 1/a) S2)`` for any ``a > 0``
   (``S2`` may be singular; ``a = sqrt(tr S2 / tr S1)`` minimises the trace), and the ball of
   step 5 joins ``S2`` the same way (:meth:`ErrorEllipsoid.propagate_shaped`). A second
   ellipsoid kept this way bounds the error under any noise in the box: the *noise bound*.

Cost: two n x n products per step (like the transition product itself), one eigenvalue
problem when the bound is read. A Kalman sample with a sparse ``e^{A dt}`` takes step 6's
product in factors, O(n^2 p), with its own allowance (:mod:`switchobs_core.bounds.kalman_map`), and from 40 states on
the bound is read in O(n^2) between verified anchors (:mod:`switchobs_core.bounds.read`). ``sqrt(trace S)``
(cheaper, larger) bounds ``||e_k||`` inside
``rho``.
"""

from __future__ import annotations

import math

import numpy as np

try:        # the gufunc behind np.linalg.eigvalsh (same LAPACK call, without its wrapper's 3 us)
    from numpy.linalg._umath_linalg import eigvalsh_lo as _eigvalsh_lo
except ImportError:     # pragma: no cover - another numpy layout: the public function
    _eigvalsh_lo = None

__all__ = ["UNIT_ROUNDOFF", "EXPM_ULPS", "gamma", "expm_error", "expm_extended", "ErrorEllipsoid",
           "verify_against_extended"]

#: Unit roundoff of IEEE double precision, ``u = 2^-53``.
UNIT_ROUNDOFF = 2.0**-53
#: Model of ``scipy.linalg.expm``'s accuracy for ``||M dt||_1 <= 1``: the computed exponential is
#: within ``EXPM_ULPS * n * u * ||e^{M dt}||_F`` of the exact one (Frobenius norm). Checked against
#: :func:`expm_extended` by :func:`expm_error` (and in the tests); a larger measured difference
#: is used instead, times 4.
EXPM_ULPS = 64.0


def gamma(m: int) -> float:
    """``gamma_m = m u / (1 - m u)``: the relative error of a length-m dot product (standard model)."""
    mu = m * UNIT_ROUNDOFF
    return mu / (1.0 - mu)


def expm_extended(M: np.ndarray, dt: float) -> np.ndarray:
    """``e^{M dt}`` in extended precision (``np.longdouble``): scaling and squaring of a Taylor
    series summed to below the extended precision's unit roundoff."""
    X = np.asarray(M, dtype=np.longdouble) * np.longdouble(dt)
    nrm = float(np.abs(X).sum(axis=0).max()) if X.size else 0.0
    s = max(0, int(math.ceil(math.log2(nrm))) + 1) if nrm > 0.5 else 0
    X = X / np.longdouble(2.0**s)
    n = X.shape[0]
    E = np.eye(n, dtype=np.longdouble)
    T = np.eye(n, dtype=np.longdouble)
    tiny = np.finfo(np.longdouble).eps / 16
    for k in range(1, 40):
        T = T @ X / np.longdouble(k)
        E = E + T
        if float(np.abs(T).max()) <= tiny * float(np.abs(E).max()):
            break
    for _ in range(s):
        E = E @ E
    return E


def expm_error(M: np.ndarray, dt: float, Phi: np.ndarray, *, check: bool = True) -> float:
    """Upper bound on ``||Phi - e^{M dt}||_F`` for the computed ``Phi`` (see :data:`EXPM_ULPS`).

    Without ``check``: the model's ``EXPM_ULPS n u ||Phi||_F``. With ``check``: 4 times the
    measured difference to :func:`expm_extended` plus that computation's own allowance (at least
    ``n u ||Phi||_F``). On a platform whose ``longdouble`` is plain double the check is not
    possible and the model, doubled, is used.
    """
    n = Phi.shape[0]
    nphi = float(np.linalg.norm(Phi))
    model = EXPM_ULPS * n * UNIT_ROUNDOFF * nphi
    if not check:
        return model
    if np.finfo(np.longdouble).eps >= UNIT_ROUNDOFF:
        return 2.0 * model
    ref = expm_extended(M, dt)
    diff = float(np.linalg.norm(np.asarray(Phi, dtype=np.longdouble) - ref))
    own = 64.0 * n * float(np.finfo(np.longdouble).eps) * nphi
    measured = 4.0 * (diff + own)
    if measured > model:    # the model did not hold for this step: say so in its place
        return measured
    return max(measured, n * UNIT_ROUNDOFF * nphi)


class ErrorEllipsoid:
    """``S`` of the module docstring: ``||e|| <= sqrt(lambda_max(S))``, updated per affine step.

    ``ell = ErrorEllipsoid(n, e0)``; ``ell.step(M, rho)`` after each step with error map ``M``
    and residual bound ``rho``; ``ell.bound()`` (tight, an eigenvalue problem) or
    ``ell.trace_bound()`` (cheap, larger).
    """

    def __init__(self, n: int, e0: float):
        self.n = int(n)
        self.S = (float(e0) ** 2) * np.eye(self.n)
        self.tr = float(np.trace(self.S))          # trace S >= ||S||_F >= lambda_max (S is PSD)
        self._g = gamma(2 * self.n + 2) * self.n
        self._diag = np.arange(self.n) * (self.n + 1)
        self._ii = np.arange(self.n)

    def propagate(self, M: np.ndarray, rho: float, fM2: float | None = None) -> tuple[np.ndarray, float]:
        """The next ``(S, trace S)`` for a step ``(M, rho)``, without keeping it. ``fM2`` is
        ``||M||_F^2`` if the caller has it."""
        S = M @ self.S @ M.T
        if fM2 is None:
            fM2 = float(np.dot(M.ravel(), M.ravel()))
        # 6. rounding of M S M': an elementwise-dominating allowance on the diagonal (||S||_F <= trace S)
        return self.propagate_product(S, self._g * fM2 * self.tr, rho)

    @property
    def g_dense(self) -> float:
        """The factor of step 6's allowance: ``eta = g_dense ||M||_F^2 trace S``."""
        return self._g

    def propagate_product(self, S: np.ndarray, eta: float, rho: float) -> tuple[np.ndarray, float]:
        """:meth:`propagate` from a product taken elsewhere: ``S`` (overwritten) with ``S + eta I``
        containing ``M S_k M'`` (:class:`~switchobs_core.bounds.kalman_map.KalmanMap`'s factored form)."""
        lam = float(S.trace()) + self.n * eta      # >= lambda_max(M S M' + eta I)
        if rho > 0.0:
            # 5. outer ellipsoid of (ellipsoid + ball)
            if lam > 0.0:
                r = math.sqrt(lam)
                S *= 1.0 + rho / r                       # (1 + a) with a = rho / r
                eta *= 1.0 + rho / r
                lam *= 1.0 + rho / r
                eta += rho * rho + rho * r               # (1 + 1/a) rho^2, without overflow
            else:
                eta += rho * rho
        # the rounding of the scaling and the sums: entrywise relative 4u, dominated on the diagonal
        eta += 4.0 * UNIT_ROUNDOFF * lam
        eta *= 1.0 + 4.0 * UNIT_ROUNDOFF
        S[self._ii, self._ii] += eta      # in place whatever S's layout (a reshape could copy)
        return S, (lam + self.n * eta) * (1.0 + 4.0 * self.n * UNIT_ROUNDOFF)

    def step(self, M: np.ndarray, rho: float, fM2: float | None = None) -> None:
        """Apply one step: ``e <- M e + r`` with ``||r|| <= rho``."""
        self.S, self.tr = self.propagate(M, rho, fM2)

    def propagate_shaped(self, M: np.ndarray, rho: float, G: np.ndarray, c: float,
                         GGt: np.ndarray | None = None) -> tuple[np.ndarray, float]:
        """The next ``(S, trace S)`` for ``e <- M e + r + G v`` with ``||r|| <= rho`` and
        ``||v||^2 <= c`` (module docstring, step 7): the added set is the degenerate ellipsoid
        ``E(c G G')`` plus the ball, so the noise fills only the directions ``G`` reaches (an
        isotropic ball of radius ``||G|| sqrt(c)`` instead is 20-30x looser for the paper's
        gains). ``GGt`` is ``G G'`` if the caller has it (its float rounding is allowed for)."""
        S = M @ self.S @ M.T
        fM2 = float(np.dot(M.ravel(), M.ravel()))
        return self.propagate_shaped_product(S, self._g * fM2 * self.tr, rho, G, c, GGt)   # step 6

    def propagate_shaped_product(self, S: np.ndarray, eta_s: float, rho: float, G: np.ndarray, c: float,
                                 GGt: np.ndarray | None = None) -> tuple[np.ndarray, float]:
        """:meth:`propagate_shaped` from a product taken elsewhere (as :meth:`propagate_product`)."""
        n = self.n
        if GGt is None:
            GGt = G @ G.T
        fG2 = float(np.dot(G.ravel(), G.ravel()))
        ts = float(S.trace()) + n * eta_s                   # trace of the S side
        Q = c * GGt
        tq = c * fG2                                        # trace of the exact c G G'
        d_q = gamma(G.shape[1] + 3) * c * fG2               # rounding of c G G': |.| <= gamma c |G||G'|
        if rho > 0.0:           # ball + E(Q + d_q I) inside E((1 + b)(Q + d_q I) + (1 + 1/b) rho^2 I)
            if tq > 0.0:        # b trace-optimal, kept in [1e-150, 1e150] (any b > 0 is valid)
                b = min(max(rho * math.sqrt(n) / math.sqrt(tq), 1e-150), 1e150)
                Q = (1.0 + b) * Q
                tq *= 1.0 + b
                d_q = (1.0 + b) * d_q + (1.0 + 1.0 / b) * rho * rho
            else:
                d_q += rho * rho
        tq += n * d_q
        if ts > 0.0 and tq > 0.0:   # E(S + eta_s I) + E(Q + d_q I): a = sqrt(tq / ts) (trace-optimal)
            a = min(max(math.sqrt(tq) / math.sqrt(ts), 1e-150), 1e150)
            S *= 1.0 + a
            S += (1.0 + 1.0 / a) * Q
            diag = (1.0 + a) * eta_s + (1.0 + 1.0 / a) * d_q
            lam = (1.0 + a) * ts + (1.0 + 1.0 / a) * tq
        else:
            S += Q
            diag = eta_s + d_q
            lam = ts + tq
        # the rounding of the scalings and sums above: entrywise relative 4u, dominated on the diagonal
        diag += 4.0 * UNIT_ROUNDOFF * lam
        diag *= 1.0 + 4.0 * UNIT_ROUNDOFF
        S.flat[self._diag] += diag
        return S, (lam + n * diag) * (1.0 + 4.0 * n * UNIT_ROUNDOFF)

    def step_shaped(self, M: np.ndarray, rho: float, G: np.ndarray, c: float,
                    GGt: np.ndarray | None = None) -> None:
        """Apply one noise step (:meth:`propagate_shaped`)."""
        self.S, self.tr = self.propagate_shaped(M, rho, G, c, GGt)

    def trace_bound(self) -> float:
        """``sqrt(trace S) >= ||e||`` (cheap)."""
        return math.sqrt(max(self.tr, 0.0))

    def bound(self, S: np.ndarray | None = None) -> float:
        """``sqrt(lambda_max(S)) >= ||e||`` (of ``S``, default the current one), inflated for the
        eigenvalue solver's own error (relative ``n u``)."""
        return math.sqrt(self.lam_upper(S))

    def lam_upper(self, S: np.ndarray | None = None) -> float:
        """``>= lambda_max((S + S') / 2)`` (of ``S``, default the current one): the eigenvalue
        problem's solution plus the solver's own error (relative ``n u``)."""
        S = self.S if S is None else S
        S = S + S.T
        S *= 0.5
        if not self.n:
            return 0.0
        nS = fro_norm(S)
        lam = math.nan
        if _eigvalsh_lo is not None and math.isfinite(nS):
            lam = float(_eigvalsh_lo(S, signature="d->d")[-1])
        if not math.isfinite(lam):      # a non-finite S, or no convergence: np.linalg's handling (raises)
            lam = float(np.linalg.eigvalsh(S)[-1])
        return max(lam, 0.0) + 2 * self.n * UNIT_ROUNDOFF * nS


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
