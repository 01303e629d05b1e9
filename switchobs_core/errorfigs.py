"""The paper's two error figures (f:error_periodic, f:error_nonperiodic), exact.

Each figure has three panels: top, ``||x_tilde_o^(i)(t)||`` with the paper's envelopes
``z_i`` (e:z1_evolution, e:z2_evolution); middle, ``||x_tilde(t)||`` on a log scale with
the paper's bound ``alpha sum z_i`` (its claim, not a guarantee) and the exact bound
``||Phi(t, 0)|| ||x_tilde(0)||`` (ours, guaranteed for continuous outputs); bottom, the
switching signal ``rho(t)``. Continuous outputs (the paper's setting), initial error
``0.1 * randn`` seeded (Section ``subsec:sim_results``).

Cases: periodic ``(2 s, 0.6)`` with ``(eta_1, eta_2) = (1.6, 3.5)``; nonperiodic
``(4, 0.5), (3, 0.6), (3, 0.6), (2, 0.4)`` repeated with the paper's selected rates
(Table ``T:eta_values``).

Paper labels (``e:...``, ``t:...``) resolve to numbers in ``docs/equations.md``.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from .design import design_cycle
from .exceptions import InvalidArgument
from .files import write_with
from .schedule import Cycle, PeriodicSchedule, SequenceSchedule
from .simulate import simulate

__all__ = ["write_error_figures", "plot_result", "PERIODIC", "NONPERIODIC", "paper_cases"]

#: (tau, s) and (eta_1, eta_2) of the paper's periodic case.
PERIODIC = (((2.0, 0.6),), ((1.6, 3.5),))
#: The paper's nonperiodic cycle list and Table ``T:eta_values`` selected rates.
NONPERIODIC = (((4.0, 0.5), (3.0, 0.6), (3.0, 0.6), (2.0, 0.4)),
               ((1.2, 1.1), (1.0, 2.2), (1.0, 2.2), (3.5, 1.5)))


def paper_cases(system: Any, table_or_designs: Any = None) -> dict:
    """``{"periodic": (schedule, designs), "nonperiodic": (...)}`` for the paper's cases.

    ``table_or_designs``: a GainTable (looked up per cycle), a dict ``{Cycle: design}``,
    or None (designed here with the paper's selected rates via ``design_cycle``).
    """
    out = {}
    for name, (ts, etas) in (("periodic", PERIODIC), ("nonperiodic", NONPERIODIC)):
        cycles = [Cycle.from_ts(*x) for x in ts]
        designs = []
        memo: dict = {}
        for c, eta in zip(cycles, etas):
            if c in memo:
                designs.append(memo[c])
                continue
            if table_or_designs is None:
                d = design_cycle(system, c, eta=eta)
            elif isinstance(table_or_designs, dict):
                d = table_or_designs[c]
            else:
                d = table_or_designs.lookup(c)
            memo[c] = d
            designs.append(d)
        sched = PeriodicSchedule(cycles[0]) if name == "periodic" else SequenceSchedule(cycles)
        out[name] = (sched, designs)
    return out


class _Table:
    """Adapter: per-cycle lookup in a fixed design list (for :func:`simulate`)."""

    def __init__(self, cycles, designs):
        self._map = list(zip(cycles, designs))
        self.robust = None

    def lookup(self, c):
        for cc, d in self._map:
            if cc.matches(c):
                return d
        raise InvalidArgument(f"no design for cycle {c.label()}")


def plot_result(res: Any, path: str | Path, title: str = "") -> Path:
    """Three-panel figure of a :class:`~switchobs_core.simulate.SimulationResult`."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    path = Path(path)
    N = res.z.shape[0]
    colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    fig, ax = plt.subplots(3, 1, figsize=(9, 8.2), sharex=True,
                           gridspec_kw={"height_ratios": [3, 3, 1.2]})
    for i in range(N):
        ax[0].plot(res.t, res.xo_norms[i], color=colors[i], lw=1.4,
                   label=rf"$\|\tilde x_o^{{({i + 1})}}(t)\|$")
        ax[0].plot(res.t, res.z[i], color=colors[i], lw=1.0, ls="--",
                   label=rf"$z_{i + 1}(t)$ (paper's envelope)")
    ax[0].set_yscale("log")
    ax[0].set_ylabel("observable error")
    ax[0].legend(ncol=2, fontsize=8, loc="lower left", framealpha=0.9)
    ax[0].grid(True, which="major", alpha=0.3)
    en = res.error_norm
    ax[1].plot(res.t, en, color="k", lw=1.5, label=r"$\|\tilde x(t)\|$")
    ax[1].plot(res.t, res.paper_bound, color=colors[3], lw=1.0, ls="--",
               label=r"paper's bound $\alpha \sum_i z_i$ (claim)")
    bound, label, status = res.guarantee()
    verdict = ("not a guarantee with noise" if label == "noise-free bound" else
               "NOT verified" if "NOT verified" in status else "verified at every output")
    ax[1].plot(res.t, res.exact_bound, color=colors[2], lw=1.2,
               label=r"exact bound $\|\Phi(t,0)\|\,e_0$, rounding included"
               + (f" (noise-free: {verdict})" if label == "noise-free bound" else
                  "" if bound is not res.exact_bound else f" ({verdict})"))
    if bound is not None and bound is not res.exact_bound:
        ax[1].plot(res.t, bound, color=colors[4], lw=1.2, ls="-.", label=f"{label} ({verdict})")
    ax[1].set_yscale("log")
    ax[1].set_ylabel("estimation error")
    ax[1].legend(fontsize=8, loc="lower left", framealpha=0.9)
    ax[1].grid(True, which="major", alpha=0.3)
    lo = max(min(en[en > 0].min() if np.any(en > 0) else 1e-12, res.exact_bound.min()) / 3, 1e-14)
    ax[1].set_ylim(lo, max(res.paper_bound.max(), res.exact_bound.max()) * 3)
    xo = res.xo_norms[res.xo_norms > 0]
    lo0 = max(xo.min() / 3, 1e-12) if xo.size else 1e-12
    ax[0].set_ylim(lo0, max(res.z.max(), res.xo_norms.max()) * 3)
    ax[2].step(res.t, res.channel, where="post", color="k", lw=1.2)
    ax[2].set_yticks(range(1, N + 1))
    ax[2].set_ylim(0.5, N + 0.5)
    ax[2].set_ylabel(r"$\rho(t)$")
    ax[2].set_xlabel("t [s]")
    ax[2].grid(True, alpha=0.3)
    if title:
        ax[0].set_title(title, fontsize=10)
    fig.tight_layout()
    try:
        write_with(path, "figure", lambda p: fig.savefig(p, dpi=130))
    finally:
        plt.close(fig)
    return path


def write_error_figures(system: Any, table_or_designs: Any, outdir: str | Path, *,
                        t_end: float = 20.0, seed: int = 0, e_scale: float = 0.1) -> list[Path]:
    """Write the paper's error figures (periodic, nonperiodic) as PNG into ``outdir``.

    Parameters
    ----------
    system : LTISystem
        The paper's model (``load_system("paper")``).
    table_or_designs : GainTable, dict or None
        See :func:`paper_cases`; None designs with the paper's selected rates.
    outdir : path
    t_end : float
        Horizon in seconds (default 20).
    seed : int
        Seed of the initial error ``e_scale * randn(n)`` and of the plant's ``x(0)``.

    Returns
    -------
    list of Path
        ``error_periodic.png``, ``error_nonperiodic.png``.
    """
    outdir = Path(outdir)
    rng = np.random.default_rng(seed)
    x0 = rng.standard_normal(system.n)
    e = e_scale * rng.standard_normal(system.n)
    paths = []
    for name, (sched, designs) in paper_cases(system, table_or_designs).items():
        table = _Table(sched.cycles, designs)
        res = simulate(system, table, sched, x0, x0 + e, t_end, mode="sequence", dt_out=0.005)
        label = ", ".join(c.label() for c in sched.cycles)
        etas = ", ".join("(" + ", ".join(f"{v:g}" for v in d.eta) + ")" for d in designs)
        title = (f"{name}: cycles {label}; eta {etas}\n"
                 rf"continuous outputs, $\tilde x(0) = {e_scale:g}\,$randn (seed {seed}); "
                 rf"$\alpha$ = {res.alpha:.3f}")
        paths.append(plot_result(res, outdir / f"error_{name}.png", title))
    return paths
