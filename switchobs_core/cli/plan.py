"""``switchobs plan``: choose the periodic schedule (not only the gains) for a system and sample rate."""

from __future__ import annotations

import argparse
import math
import shlex
from pathlib import Path
from typing import Any

import numpy as np

from ..design.kalman import sample_pattern
from ..design.plan import ScheduleCost, cost_map, cycle_cost, gain_reports, plan_schedule
from ..exceptions import DesignError, InvalidArgument, ScheduleError
from ..files import check_output, write_with
from ..model.scenarios import load_noise, load_system
from ..model.schedule import Cycle
from ..paper import TABLE
from ._common import add_dead_time, fmt_table, print_json

__all__ = ["register", "run", "design_command", "fmt_num"]

COST_KIND = ("mean over the samples of one period of tr(W P^-_k), P^- the a-priori covariance of the periodic "
             "Kalman filter")


#: Largest ``--map-size`` M: the (tau, s) map costs M^2 periodic Riccati solves (64: about 4000).
MAX_MAP_SIZE = 64

def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "plan",
        help="choose the periodic schedule with the smallest steady Kalman covariance at a sample rate",
        description=(
            "Search the periodic schedules with active times on the sample grid (h_i = k_i / rate, "
            "h_i >= --h-min, tau <= --tau-max) for the least time-averaged (weighted) trace of the periodic "
            "Kalman filter's a-priori covariance; report it with the paper's LMI design and the certified "
            "decay rates of both gain families, and the `switchobs design` command for it."
        ),
        epilog="example: switchobs plan paper --rate 100 --h-min 0.5 --tau-max 4 --plot map.png",
    )
    p.add_argument("config", help="built-in scenario name (paper, camera_agents) or a system YAML file")
    p.add_argument("--rate", type=float, required=True, metavar="HZ", help="nominal sample rate in Hz")
    p.add_argument("--meas-noise", type=float, metavar="STD",
                   help="measurement noise std on every output row (default: the system's noise: section, 1 mm)")
    p.add_argument("--process-noise", type=float, metavar="Q",
                   help="process noise q on every state (Q_c = q^2 I), as for `switchobs design --gains kalman`")
    p.add_argument("--h-min", type=float, default=0.5, metavar="S",
                   help="shortest active time of a channel in seconds (default 0.5)")
    p.add_argument("--tau-max", type=float, default=4.0, metavar="S",
                   help="longest cycle in seconds (default 4, the paper's longest cycle)")
    add_dead_time(p)
    p.add_argument("--weights", metavar="W",
                   help="diagonal state weights of the cost: n comma-separated numbers, or state-label patterns "
                   "(fnmatch, optionally =weight; other states 0), e.g. 'agent*.p_*' (agent positions only)")
    p.add_argument("--delta", type=float, default=0.99, help="delta of the paper's LMI design reported (default 0.99)")
    p.add_argument("--plot", type=Path, metavar="PNG",
                   help="write a map of log10 cost over (tau, s) (two channels), optimum and paper cycles marked")
    p.add_argument("--map-size", type=int, default=12, metavar="M",
                   help="the map's grid is M x M (tau, s) points (default 12)")
    p.add_argument("--json", action="store_true", help="print the result as JSON (no progress bar)")
    p.add_argument("--progress", action=argparse.BooleanOptionalAction, default=None,
                   help="progress bar on stderr (default: on a terminal, off with --json)")
    p.set_defaults(func=run)


def fmt_num(x: float) -> str:
    """Shortest decimal text that reads back as exactly ``x`` (``%.12g`` when that round-trips)."""
    s = f"{x:.12g}"
    return s if float(s) == x else repr(float(x))


def _cycle_args(cycle: Cycle) -> tuple[list[str], Cycle]:
    """The ``--cycle``/``--cycle-h`` arguments for ``cycle`` and the cycle ``switchobs design`` reads from them."""
    dead = ["--dead-time", fmt_num(cycle.dead_time)] if cycle.dead_time else []
    if cycle.N == 2:
        tau, s = fmt_num(cycle.tau), fmt_num(cycle.h[0] / cycle.tau)
        return ["--cycle", f"{tau},{s}", *dead], Cycle.from_ts(float(tau), float(s), cycle.dead_time)
    hs = [fmt_num(h) for h in cycle.h]
    return ["--cycle-h", ",".join(hs), *dead], Cycle([float(h) for h in hs], cycle.dead_time)


def design_command(config: str, cycle: Cycle, *, rate: float | None = None, meas_noise: float | None = None,
                   process_noise: float | None = None, output: str = "gains.json") -> tuple[str, Cycle]:
    """The ``switchobs design`` command line for ``cycle`` (kalman gains when ``rate`` is given) and the cycle it
    designs for."""
    cyc_args, read = _cycle_args(cycle)
    argv = ["switchobs", "design", config, *cyc_args]
    if rate is not None:
        argv += ["--gains", "kalman", "--rate", fmt_num(rate)]
        if meas_noise is not None:
            argv += ["--meas-noise", fmt_num(meas_noise)]
        if process_noise is not None:
            argv += ["--process-noise", fmt_num(process_noise)]
    argv += ["-o", output]
    return shlex.join(argv), read


def _paper_rows(J: ScheduleCost) -> list[dict]:
    rows = []
    for (tau, s), _, _ in TABLE:
        c = Cycle.from_ts(tau, s)
        try:
            val = cycle_cost(J, c.with_dead_time(J.dead_time))
        except (DesignError, ScheduleError) as err:
            val, why = None, str(err)
        else:
            why = None
        rows.append({"tau": tau, "s": s, "h": list(c.h), "cost": val, "reason": why})
    return rows


def _plot(path: Path, J: ScheduleCost, res: Any, paper: list[dict], h_min: float, tau_max: float, M: int,
          progress: bool | None) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    tau_lo = 2 * res.k_min / J.rate
    taus = np.unique(np.round(np.linspace(tau_lo, res.k_total_max / J.rate, M) * J.rate)) / J.rate
    s_vals = np.linspace(0.05, 0.95, M if M % 2 else M + 1)   # odd: s = 0.5 is on the grid
    grid = cost_map(J, taus, s_vals, res.k_min, progress=progress)
    with np.errstate(divide="ignore", invalid="ignore"):
        Z = np.log10(grid)
    Z[~np.isfinite(Z)] = np.nan
    fig, ax = plt.subplots(figsize=(6.8, 4.8), constrained_layout=True)
    pc = ax.pcolormesh(taus, s_vals, Z.T, shading="nearest", cmap="viridis")
    fig.colorbar(pc, ax=ax, label="log10 cost  (mean tr(W P^-) over a period)")
    ax.plot([res.tau], [res.counts[0] / sum(res.counts)], "r*", ms=16, mec="w", label=f"plan ({res.cycle.label()})")
    pts = [r for r in paper if r["cost"] is not None]
    if pts:
        ax.plot([r["tau"] for r in pts], [r["s"] for r in pts], "wo", mec="k", ms=8, label="the paper's cycles")
    ax.set_xlabel("cycle length tau [s]")
    ax.set_ylabel("duty fraction s (channel 1 active s*tau)")
    ax.set_title(f"Periodic Kalman cost at {J.rate:g} Hz, h >= {h_min:g} s (grey: excluded)", fontsize=10)
    ax.set_facecolor("0.85")
    ax.legend(loc="upper right", fontsize=8)
    try:
        write_with(path, "--plot", lambda p: fig.savefig(p, dpi=110))
    finally:
        plt.close(fig)


def run(args: argparse.Namespace) -> int:
    system = load_system(args.config)
    noise = load_noise(args.config, system, meas_std=args.meas_noise, process_q=args.process_noise)
    progress = False if args.json else args.progress
    if args.plot is not None:
        check_output(args.plot, "--plot")     # before the search, not after it
    if not 3 <= args.map_size <= MAX_MAP_SIZE:
        raise InvalidArgument(f"--map-size must be in [3, {MAX_MAP_SIZE}] (the map costs M^2 Riccati solves); "
                              f"got {args.map_size}")
    if not (math.isfinite(args.dead_time) and args.dead_time >= 0):
        raise InvalidArgument(f"--dead-time must be a finite number of seconds >= 0; got {args.dead_time:g}")
    J = ScheduleCost(system, args.rate, noise, args.weights, dead_time=args.dead_time)
    res = plan_schedule(system, args.rate, noise, h_min=args.h_min, tau_max=args.tau_max, progress=progress, cost=J)
    cmd, read = design_command(args.config, res.cycle, rate=J.rate, meas_noise=args.meas_noise,
                               process_noise=args.process_noise)
    cmd_lmi, _ = design_command(args.config, res.cycle)
    extras = gain_reports(system, read, J.rate, noise, delta=args.delta)
    planned_channels = J.channels(res.counts)
    kal = extras["kalman"]
    matches = kal.get("channels") is not None and tuple(kal["channels"]) == planned_channels
    paper = _paper_rows(J) if system.N == 2 else []
    if args.plot is not None:
        if system.N != 2:
            raise DesignError("--plot draws the (tau, s) map of a two-channel system")
        _plot(args.plot, J, res, paper, args.h_min, args.tau_max, max(3, args.map_size), progress)
    out = {
        "system": system.name,
        "rate": J.rate,
        "tau": read.tau,
        "h": list(res.h),
        "s": read.s if system.N == 2 else None,
        "delta": args.delta,
        "counts": list(res.counts),
        "cost": res.cost,
        "cost_kind": COST_KIND,
        "weights": res.weights.tolist(),
        "dead_time": args.dead_time,
        "h_min": args.h_min,
        "tau_max": args.tau_max,
        "evaluations": res.evaluations,
        "local_minimum": res.local_minimum,
        "design_command": cmd,
        "design_command_lmi": cmd_lmi if extras["lmi"]["feasible"] else None,   # never a design found infeasible
        "design_pattern_matches": matches,
        "cost_as_designed": res.cost if matches or "channels" not in kal else
        J.of_channels(kal["channels"], (read,), sample_pattern(read, J.rate).blind),
        "lmi": extras["lmi"],
        "kalman": {k: v for k, v in kal.items() if k != "channels"},
        "paper_cycles": paper,
        "other_orders": [{"order": list(a["order"]), "counts": list(a["counts"]), "cost": a["cost"]}
                         for a in res.alternatives],
    }
    if args.plot is not None:
        out["plot"] = str(args.plot)
    if args.json:
        print_json(_finite(out))
        return 0
    _print_text(out, res, system)
    return 0


def _finite(obj: Any) -> Any:
    """JSON has no inf: infinite numbers become null."""
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    if isinstance(obj, dict):
        return {k: _finite(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_finite(v) for v in obj]
    return obj


def _print_text(out: dict, res: Any, system: Any) -> None:
    N = system.N
    best = out["cost"]
    rows = [["planned", fmt_num(out["tau"]), "-" if N != 2 else f"{out['s']:.4g}",
             ", ".join(f"{h:g}" for h in out["h"]), f"{best:.4e}", "1.000"]]
    for r in out["paper_cycles"]:
        c = r["cost"]
        rows.append([f"paper ({r['tau']:g} s, {r['s']:g})", f"{r['tau']:g}", f"{r['s']:g}",
                     ", ".join(f"{h:g}" for h in r["h"]), "-" if c is None else f"{c:.4e}",
                     "-" if c is None else f"{c / best:.3f}"])
    for a in out["other_orders"]:
        rows.append([f"order {a['order']}", fmt_num(sum(a["counts"]) / out["rate"]), "-",
                     ", ".join(f"{k / out['rate']:g}" for k in a["counts"]), f"{a['cost']:.4e}",
                     f"{a['cost'] / best:.3f}"])
    print(f"plan for '{system.name}' at {out['rate']:g} Hz, h >= {out['h_min']:g} s, tau <= {out['tau_max']:g} s"
          + (f", dead time {out['dead_time']:g} s after each switch" if out["dead_time"] else ""))
    print(fmt_table(["schedule", "tau [s]", "s", "h [s]", "cost", "cost / planned"], rows))
    w = np.asarray(out["weights"])
    wtxt = "W = I" if np.all(w == 1) else "W = diag(" + ", ".join(f"{v:g}" for v in w) + ")"
    print(f"cost: {COST_KIND}, {wtxt}; {out['evaluations']} evaluations; "
          + ("local minimum (no +-1 sample neighbour is better)" if out["local_minimum"] else "NOT a local minimum"))
    lmi = out["lmi"]
    if lmi["feasible"]:
        print(f"lmi gains (the paper's, delta {out['delta']:g}): eta_min = "
              + ", ".join(f"{e:.4g}" for e in lmi["eta_min"])
              + f"; certified decay rate {lmi['certified_rate']:.4g} 1/s (cycle transition rho "
              f"{lmi['spectral_radius']:.4g}, continuous outputs)")
    else:
        print(f"lmi gains (the paper's): infeasible: {lmi['reason']}")
    k = out["kalman"]
    if "reason" in k:
        print(f"kalman gains: failed: {k['reason']}")
    else:
        print(f"kalman gains at {out['rate']:g} Hz: certified decay rate {k['certified_rate']:.4g} 1/s (period "
              f"error map rho {k['spectral_radius']:.4g} over {k['period']:g} s)")
    if not out["design_pattern_matches"]:
        print("note: `switchobs design` assigns a sample at a switching instant to the other channel in floating "
              f"point (a tie); the cost of its sample pattern is {out['cost_as_designed']:.4e}")
    print(f"design: {out['design_command']}")
    if out["design_command_lmi"]:
        print(f"        {out['design_command_lmi']}")
    else:
        print("        (no LMI design command: the paper's LMI gains are infeasible for this cycle, see above; "
              "design the Kalman gains)")
    dead = f", schedule.dead_time: {fmt_num(out['dead_time'])}" if out["dead_time"] else ""
    if N == 2:
        print(f"ROS parameters: schedule.tau: [{fmt_num(out['tau'])}], schedule.s: [{fmt_num(out['s'])}]{dead}")
    else:
        print(f"ROS parameters: schedule.h: [{', '.join(fmt_num(h) for h in out['h'])}]{dead}")
    if "plot" in out:
        print(f"wrote {out['plot']}")

