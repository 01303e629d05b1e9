"""The paper's design figures: eta_min over (tau, s) (f:eta_min1, f:eta_min2) and kappa*(eta)
(f:kappa_LMI). Matplotlib with the Agg backend; PNG files.

Paper labels (``e:...``, ``t:...``) resolve to numbers in ``docs/equations.md``.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from ..design.lmi import Designer
from ..files import write_with

__all__ = ["eta_min_figures", "kappa_figure", "TAUS", "S_VALUES"]

TAUS = (1.0, 2.0, 3.0, 4.0, 5.0)
S_VALUES = tuple(np.round(np.linspace(0.01, 0.99, 99), 2))


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def eta_min_figures(
    designer: Designer,
    outdir: Path,
    *,
    taus: Sequence[float] = TAUS,
    s_values: Sequence[float] = S_VALUES,
    progress: bool | None = None,
) -> list[Path]:
    """eta_min_i(tau, s) curves for both channels (the paper's design-region figures)."""
    plt = _plt()
    outdir.mkdir(parents=True, exist_ok=True)
    grid = designer.eta_min_map(taus, s_values, progress=progress)
    s = np.asarray(s_values)
    paths = []
    for i in range(2):
        fig, ax = plt.subplots(figsize=(6.4, 4.2), constrained_layout=True)
        bad = []
        for a, tau in enumerate(taus):
            (line,) = ax.plot(s, grid[a, :, i], label=f"tau = {tau:g} s")
            bad += [(x, line.get_color()) for x, v in zip(s, grid[a, :, i]) if not np.isfinite(v)]
        ax.set_yscale("log")
        if bad:  # points with no admissible eta: marked on the top edge, not silently dropped
            top = ax.get_ylim()[1] if np.isfinite(grid[:, :, i]).any() else 1.0
            for k, (x, c) in enumerate(bad):
                ax.plot([x], [top], "x", color=c, clip_on=False, label="no admissible eta" if k == 0 else None)
        ax.set_xlabel("duty fraction s (channel 1 active for s*tau)")
        ax.set_ylabel(f"eta_min^({i + 1})")
        ax.set_title(f"Minimum decay rate of channel {i + 1} (delta = {designer.delta[i]:g})")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend()
        p = outdir / f"eta_min{i + 1}.png"
        write_with(p, "figure", lambda q, fig=fig: fig.savefig(q, dpi=120))
        plt.close(fig)
        paths.append(p)
    return paths


def kappa_figure(designer: Designer, outdir: Path, *, etas: Sequence[float] | None = None, oracle=None) -> Path:
    """kappa_i*(eta) from the SDP for every channel (f:kappa_LMI); ``oracle(eta, i)`` dashed if given."""
    plt = _plt()
    outdir.mkdir(parents=True, exist_ok=True)
    etas = np.linspace(0.0, 6.0, 61) if etas is None else np.asarray(etas)
    fig, ax = plt.subplots(figsize=(6.4, 4.2), constrained_layout=True)
    for i, ch in enumerate(designer.channels):
        k = np.array([ch.curve.raw(e) for e in etas])
        ax.plot(etas, k, lw=2, label=f"channel {i + 1}: sqrt(theta*) from the SDP")
        if oracle is not None:
            ax.plot(
                etas,
                [oracle(e, i + 1) for e in etas],
                "k--",
                lw=1,
                label="closed form a + sqrt(1 + a^2)" if i == 0 else None,
            )
    ax.set_xlabel("decay rate eta")
    ax.set_ylabel("kappa*(eta)")
    ax.set_title("Minimum bound constant kappa* of the LMI synthesis")
    ax.grid(True, alpha=0.3)
    ax.legend()
    p = outdir / "kappa_LMI.png"
    write_with(p, "figure", lambda q: fig.savefig(q, dpi=120))
    plt.close(fig)
    return p
