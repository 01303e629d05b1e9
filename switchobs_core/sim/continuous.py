"""The paper's continuous-output setting as one linear system (Sections 2 and 4).

With ``y(t) = C_rho(t) x(t)`` available at every instant, the observer (e:switched_observer) is
not a run-time object fed with samples (that is :class:`~switchobs_core.runtime.observer.SwitchedObserver`,
which :func:`switchobs_core.sim.simulate.simulate` runs for sampled outputs): it is the lower
block of the joint system of plant (e:system) and observer, linear between switching instants,

.. math::

    \\frac{d}{dt}\\begin{bmatrix} x \\\\ \\hat x \\end{bmatrix}
    = \\begin{bmatrix} A & 0 \\\\ L_i C_i & A - L_i C_i \\end{bmatrix}
      \\begin{bmatrix} x \\\\ \\hat x \\end{bmatrix}
    + \\begin{bmatrix} B \\\\ B \\end{bmatrix} u ,

whose error ``x_tilde = x_hat - x`` obeys (e:xtilde_dyn_piecewise) exactly.
:func:`continuous_outputs` propagates it by augmented matrix exponentials on the output grid
(``u`` held on each grid step, seeded process noise of the exact discretised covariance) and
keeps the exact bound of the *computed* pair.

Paper labels (``e:...``, ``t:...``) resolve to numbers in ``docs/equations.md``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..bounds.envelope import Segment
from ..numerics.expm_bound import certify_zoh, expm_error_bound
from ..numerics.propagation import van_loan, zoh_pair
from ..numerics.rounding import UNIT_ROUNDOFF, ErrorEllipsoid, gamma
from .plant import input_at
from .progress import progress_bar

__all__ = ["ContinuousRun", "continuous_outputs"]


@dataclass(frozen=True)
class ContinuousRun:
    """The joint system's trajectory on the output grid ``t`` (grid points and switching instants).

    ``x``, ``x_hat`` (T, n); ``channel`` (T,) active from ``t`` on (1-based); ``exact_bound`` (T,)
    on ``||x_hat - x||`` of the computed pair (:func:`continuous_outputs`)."""

    t: np.ndarray
    x: np.ndarray
    x_hat: np.ndarray
    channel: np.ndarray
    exact_bound: np.ndarray


def continuous_outputs(A: np.ndarray, B: np.ndarray, C: Sequence[np.ndarray], segments: Sequence[Segment],
                       x0: np.ndarray, xhat0: np.ndarray, t0: float, t_end: float, dt_out: float, u: Any,
                       process_noise: Any, seed: int, e0: float, *, progress: bool | None = False) -> ContinuousRun:
    """Joint ``(x, x_hat)`` propagation between grid points and switching instants, with the exact
    bound of the *computed* pair (module docstring).

    ``segments`` are the active intervals (:func:`~switchobs_core.bounds.envelope.schedule_segments`);
    ``B`` is (n, m) (m = 0 without an input), ``u`` a vector, ``t -> u`` or None. The arguments are
    the ones :func:`~switchobs_core.sim.simulate.simulate` has checked (the simulator's step, not
    an entry point of its own).

    Bound (the argument of :mod:`switchobs_core.numerics.rounding` on the joint step): the computed pair
    obeys ``z_{k+1} = fl(J~ z_k)`` with ``J~`` the computed ``e^{J dt}``; the exact joint map
    keeps ``x_hat - x`` on ``e_{k+1} = E e_k`` (``E = e^{(A - L C) dt}``, the lower-right block
    of ``e^{J dt}``, since ``J`` is block triangular). Hence the computed difference obeys
    ``e_{k+1} = H~ e_k + r_k`` with ``H~`` the computed lower-right block and
    ``||r_k|| <= sqrt(2) (eps_J + gamma_{2n+2} ||J~||_F) ||z_k|| + eps_J ||e_k||`` (``eps_J``
    proven by :func:`~switchobs_core.numerics.expm_bound.certify_zoh`), plus the input's term; an
    :class:`~switchobs_core.numerics.rounding.ErrorEllipsoid` keeps ``||e_k||``. The bound covers the
    error column as computed (``x_hat - x`` rounded, a factor ``1 + 2u``): the difference between
    the computed estimate and the computed plant that drives it.
    """
    n, m = B.shape
    grid = t0 + dt_out * np.arange(int(math.floor((t_end - t0) / dt_out + 1e-9)) + 1)
    grid = np.union1d(grid[grid <= t_end], [s.t0 for s in segments] + [t_end])
    Qc = np.asarray(process_noise, dtype=float)
    if Qc.ndim == 0:
        Qc = float(Qc) ** 2 * np.eye(n)
    noisy = bool(np.any(Qc))
    rng = np.random.default_rng(seed)
    Qj = np.zeros((2 * n, 2 * n))
    Qj[:n, :n] = Qc
    Bj = np.vstack([B, B])
    zc = np.concatenate([x0, xhat0])
    out = np.empty((grid.size, 2 * n))
    ch = np.empty(grid.size, dtype=int)
    cache: dict = {}
    si = 0
    ell = ErrorEllipsoid(n, e0)
    exact = np.empty(grid.size)
    g2n, gm = gamma(2 * n + 2), gamma(m + 2)
    for k, tk in enumerate(progress_bar(grid, progress, "step")):
        if k > 0:
            ta = grid[k - 1]
            seg = segments[si]
            dt = tk - ta
            key = (id(seg.design), seg.channel, seg.part, dt)
            step = cache.get(key)
            if step is None:
                Ci = C[seg.channel - 1]
                L = seg.L
                J = np.zeros((2 * n, 2 * n))
                J[:n, :n] = A
                J[n:, :n] = L @ Ci
                J[n:, n:] = A - L @ Ci
                Phi, Gam = zoh_pair(J, dt)
                Lq = None
                if noisy:
                    _, Qd = van_loan(J, Qj, dt)
                    w, V = np.linalg.eigh(Qd)
                    Lq = V * np.sqrt(np.clip(w, 0, None))
                GB = Gam @ Bj
                cert = certify_zoh(J, dt, gamma_too=m > 0)
                eps = expm_error_bound(Phi, cert.E, cert.dE)
                fGB = float(np.linalg.norm(GB))
                # the input's effect on x_hat - x is 0 exactly; computed: the rows' difference,
                # Gamma's proven error through B and the rounding of GB u
                epsG = expm_error_bound(Gam, cert.G, cert.dG) if m > 0 else 0.0
                du = (float(np.linalg.norm(GB[n:] - GB[:n])) + 2.0 * epsG * float(np.linalg.norm(Bj))
                      + gm * fGB)
                step = cache[key] = (Phi, GB, Lq, np.ascontiguousarray(Phi[n:, n:]), eps,
                                     math.sqrt(2.0) * (eps + g2n * float(np.linalg.norm(Phi))), du)
            Phi, GB, Lq, H, eps, rz, du = step
            rho = rz * math.sqrt(float(zc @ zc)) + eps * ell.trace_bound()
            zc = Phi @ zc
            uk = input_at(u, ta, m)
            if uk is not None:
                zc += GB @ uk
                rho += du * math.sqrt(float(uk @ uk))
            if Lq is not None:
                zc += Lq @ rng.standard_normal(2 * n)
            ell.step(H, rho * (1.0 + gamma(8)))
        while si + 1 < len(segments) and segments[si + 1].t0 <= tk:
            si += 1
        out[k] = zc
        ch[k] = segments[si].channel
        exact[k] = ell.bound() * (1.0 + 2.0 * UNIT_ROUNDOFF)
    return ContinuousRun(grid, out[:, :n], out[:, n:], ch, exact)
