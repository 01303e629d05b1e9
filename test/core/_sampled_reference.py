"""An independent sampled observer, the tests' cross-implementation check of SwitchedObserver (not
a test module).

The exact plant (:class:`~switchobs_core.sim.plant.Plant`) is advanced to every sample
``t_k = t0 + k / rate`` and measured on the channel of the schedule's active interval; the
observer is propagated with its own steps, ``expm`` of the augmented matrices directly
(:func:`~switchobs_core.numerics.propagation.zoh_pair`, one per step length, no step
quantisation and no rounding bound), with the gain of the interval's design and the sample's
innovation (``hold="innovation"``) or the sample itself (``hold="measurement"``) held:

* innovation: ``x_hat+ = e^{A dt} x_hat + Gamma_A (L nu + B u)``, ``nu = y - C x_hat(t_k)``;
* measurement: ``x_hat+ = e^{M dt} x_hat + Gamma_M (L y + B u)``, ``M = A - L C``.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
from scipy.linalg import expm

from switchobs_core.numerics.propagation import zoh_pair
from switchobs_core.sim.plant import Plant


def sampled_reference(A, B, C, segments, x0, xhat0, t0, t_end, rate, noise_std, seed, hold="innovation"):
    """``(t, x_hat, channel, y)`` of the reference observer on the samples of ``segments``
    (:func:`~switchobs_core.bounds.envelope.schedule_segments`), no input, seeded noise."""
    n = A.shape[0]
    K = int(np.floor((t_end - t0) * rate + 1e-9))
    ts = t0 + np.arange(K + 1) / rate
    plant = Plant(SimpleNamespace(A=A, B=B, C=C), x0, seed=seed, t0=t0)
    Xh = np.empty((ts.size, n))
    ch = np.empty(ts.size, dtype=int)
    xh = np.array(xhat0, dtype=float)
    steps: dict = {}
    si = 0
    held = None         # (segment, held vector)
    ys = []
    for k, tk in enumerate(ts):
        if k > 0:
            dt = tk - ts[k - 1]
            seg, v = held
            key = (id(seg.design), seg.channel, seg.part, dt)
            if key not in steps:
                Ci, L = C[seg.channel - 1], seg.L
                if hold == "innovation":
                    _, GamA = zoh_pair(A, dt)
                    steps[key] = (expm(A * dt), GamA @ L)
                else:
                    Phi, Gam = zoh_pair(A - L @ Ci, dt)
                    steps[key] = (Phi, Gam @ L)
            Phi, GL = steps[key]
            xh = Phi @ xh + GL @ v
            plant.advance(tk)
        while si + 1 < len(segments) and segments[si + 1].t0 <= tk:
            si += 1
        seg = segments[si]
        y = plant.measure(seg.channel, noise_std)
        ys.append(y)
        held = (seg, y - C[seg.channel - 1] @ xh if hold == "innovation" else y)
        Xh[k], ch[k] = xh, seg.channel
    return ts, Xh, ch, ys
