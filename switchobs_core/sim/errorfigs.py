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

import textwrap
from pathlib import Path
from typing import Any

import numpy as np

from ..design.lmi import design_cycle
from ..exceptions import InvalidArgument
from ..files import write_with
from ..model.schedule import Cycle, PeriodicSchedule, SequenceSchedule
from .simulate import simulate

__all__ = ["write_error_figures", "error_figure", "figure_curves", "plot_result", "PERIODIC", "NONPERIODIC",
           "paper_cases"]

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


def figure_curves(res: Any) -> dict:
    """What the figure of ``res`` draws, decided once: ``{"top": [...], "middle": [...], "note": str}``
    with each curve ``(label, values, style)``.

    Only what applies is drawn and named in a legend:

    - the paper's envelopes ``z_i`` and its bound ``alpha sum z_i`` only for the paper's LMI gains
      (for the Kalman families they are not defined);
    - one bound in the middle panel, the one :meth:`SimulationResult.guarantee` names: the
      exact bound for noise-free outputs, the bounded-noise bound with a declared noise bound,
      the measurement-hold bound with measurement hold. With noise and no declared bound no
      bound is drawn (the noise-free bound lies decades under the noisy error and is no
      guarantee); ``note`` says so.
    """
    paper = res.family == "lmi"
    N = res.z.shape[0]
    top = [(rf"$\|\tilde x_o^{{({i + 1})}}(t)\|$", res.xo_norms[i], ("solid", i)) for i in range(N)]
    if paper:
        top += [(rf"$z_{i + 1}(t)$" + "\n(paper's envelope)", res.z[i], ("dashed", i)) for i in range(N)]
    middle = [(r"$\|\tilde x(t)\|$", res.error_norm, ("error", 0))]
    if paper:
        middle.append((r"paper's bound $\alpha \sum_i z_i$" + "\n(its claim)", res.paper_bound, ("paper", 0)))
    bound, label, status = res.guarantee()
    verdict = "NOT verified" if "NOT verified" in status else "verified at\nevery output"
    note = ""
    if label == "noise-free bound":
        note = ("no bound drawn: the outputs are noisy and no noise bound is declared (--noise-max), so there is "
                "no guarantee; the noise-free bound ||Phi|| e0 would lie far under the error")
    elif bound is res.noise_bound:
        middle.append(("guaranteed bound under the\n" + r"declared noise $|v| \leq v_{max}$" + f"\n({verdict})", bound,
                       ("bound", 0)))
    elif bound is res.exact_bound:
        middle.append((r"guaranteed bound $\|\Phi(t,0)\|\,e_0$," + f"\nrounding included\n({verdict})", bound,
                       ("bound", 0)))
    else:
        middle.append((f"{label},\nmeasurement hold\n({verdict})", bound, ("bound", 0)))
    if not paper:
        note = (note + "; " if note else "") + (f"{res.family} gains: the paper's envelopes z_i and its bound "
                                                "apply to its LMI gains only and are not drawn")
    return {"top": top, "middle": middle, "note": note}


def _positive_range(curves: list) -> tuple[float, float]:
    vals = np.concatenate([np.asarray(v, dtype=float).ravel() for _, v, _ in curves])
    vals = vals[np.isfinite(vals) & (vals > 0)]
    if not vals.size:
        return 1e-12, 1.0
    return max(vals.min() / 3, 1e-14), vals.max() * 3


def error_figure(res: Any, title: str = "") -> Any:
    """The three-panel matplotlib figure of a :class:`~switchobs_core.sim.result.SimulationResult`
    (:func:`figure_curves` decides what is drawn); legends sit beside the panels, never on the
    curves."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    N = res.z.shape[0]
    colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    spec = figure_curves(res)
    fig, ax = plt.subplots(3, 1, figsize=(11, 8.2), sharex=True, layout="constrained",
                           gridspec_kw={"height_ratios": [3, 3, 1.2]})
    for label, values, (style, i) in spec["top"]:
        ax[0].plot(res.t, values, color=colors[i % len(colors)], lw=1.4 if style == "solid" else 1.0,
                   ls="-" if style == "solid" else "--", label=label)
    styles = {"error": dict(color="k", lw=1.5), "paper": dict(color=colors[3], lw=1.0, ls="--"),
              "bound": dict(color=colors[2], lw=1.4)}
    for label, values, (style, _) in spec["middle"]:
        ax[1].plot(res.t, values, label=label, **styles[style])
    for a, key, ylabel in ((ax[0], "top", "observable error"), (ax[1], "middle", "estimation error")):
        a.set_yscale("log")
        a.set_ylabel(ylabel)
        a.set_ylim(*_positive_range(spec[key]))
        a.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0)
        a.grid(True, which="major", alpha=0.3)
    if spec["note"]:
        ax[1].text(0.01, 0.02, "\n".join(textwrap.wrap(spec["note"], 110)), transform=ax[1].transAxes, fontsize=7.5,
                   va="bottom", ha="left", bbox=dict(facecolor="white", alpha=0.85, lw=0))
    ax[2].step(res.t, res.channel, where="post", color="k", lw=1.2)
    ax[2].set_yticks(range(1, N + 1))
    ax[2].set_ylim(0.5, N + 0.5)
    ax[2].set_ylabel(r"$\rho(t)$")
    ax[2].set_xlabel("t [s]")
    ax[2].grid(True, alpha=0.3)
    if title:
        ax[0].set_title(title, fontsize=10)
    return fig


def plot_result(res: Any, path: str | Path, title: str = "") -> Path:
    """Write :func:`error_figure` of ``res`` to ``path`` (format from its suffix)."""
    import matplotlib.pyplot as plt

    path = Path(path)
    fig = error_figure(res, title)
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
