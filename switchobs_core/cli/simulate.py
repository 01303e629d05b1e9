"""``switchobs simulate``: exact plant + switched observer simulation with bounds."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from ..exceptions import InvalidArgument, ScheduleError
from ..files import check_output
from ..model.scenarios import load_system
from ..model.schedule import RandomSchedule, parse_schedule
from ..ranges import check_range
from ..runtime.bound_option import BOUND_FORMS
from ..sim.errorfigs import plot_result
from ..sim.simulate import simulate
from ..table.gains import GainTable
from ._common import add_dead_time, fmt_table, print_json

__all__ = ["register", "run", "warn_a2"]

#: Figure formats ``--plot`` writes (matplotlib's, by file name).
PLOT_SUFFIXES = (".png", ".pdf", ".svg", ".jpg", ".jpeg", ".eps", ".ps", ".tif", ".tiff", ".webp")


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "simulate",
        help="simulate plant and switched observer exactly; print errors and bounds",
        description=(
            "Simulate the plant and the switched observer with a gain table, exactly (matrix "
            "exponentials). Without --rate the outputs are continuous (the paper's setting); with "
            "--rate they are sampled and held. Prints the error at cycle ends, the paper's bound "
            "(its claim) and the bound that is guaranteed for the run's setting (none with noise)."
        ),
    )
    p.add_argument("config", help="scenario name (e.g. paper) or system YAML file")
    p.add_argument("--table", type=Path, required=True, help="gain table file")
    p.add_argument("--schedule", default="periodic:2,0.6",
                   help="periodic:TAU,S | periodic-h:H1,..,HN | sequence:T,S;T,S;... | random:HMIN,HMAX[,SEED] "
                        "(random uses the table's robust design)")
    add_dead_time(p)
    p.add_argument("--t-end", type=float, default=60.0, help="end time in seconds (default 60)")
    p.add_argument("--rate", type=float, default=None, help="sample rate in Hz (default: continuous outputs)")
    p.add_argument("--noise", type=float, default=0.0, help="measurement noise std (needs --rate)")
    p.add_argument("--noise-max", type=float, default=None, metavar="VMAX",
                   help="declare a bound |v| <= VMAX on every measurement row (needs --rate): the noise "
                        "draws are clipped to it and the run gets a guaranteed bound under that noise")
    p.add_argument("--bound", choices=BOUND_FORMS, default="ellipsoid",
                   help="form of the rigorous bounds: ellipsoid (default) or, for a kalman table, phase (scalars "
                        "per phase of the table's grid: cheaper per sample, about 3x looser)")
    p.add_argument("--hold", choices=("innovation", "measurement"), default="innovation",
                   help="with --rate: hold the innovation (default; error independent of the plant) "
                        "or the measurement between samples")
    p.add_argument("--process-noise", type=float, default=0.0, help="process noise spectral density (std)")
    p.add_argument("--e0", type=float, default=0.1,
                   help="scale of a random initial error: x_hat(0) = x(0) + E0 * randn(n), so ||x_hat(0) - x(0)|| "
                        "is about E0 sqrt(n) (default 0.1; the node's e0 is a bound on that norm, not a scale)")
    p.add_argument("--seed", type=int, default=0, help="seed of x(0), the initial error and the noise")
    p.add_argument("--plot", type=Path, metavar="PNG", help="write the three-panel error figure")
    p.add_argument("--progress", action=argparse.BooleanOptionalAction, default=None,
                   help="progress bar over the simulated samples (default: on a terminal)")
    p.add_argument("--json", action="store_true", help="print a JSON summary")
    p.set_defaults(func=run)


def warn_a2(schedule, table) -> None:
    """A warning on stderr where a random schedule's residence times leave the robust design's
    box (assumption A2): the paper's envelope does not cover them (the exact bound still holds:
    it follows the gains actually applied)."""
    box = getattr(getattr(table, "robust", None), "h_bounds", None)
    if isinstance(schedule, RandomSchedule) and box is not None:
        lo, hi = box
        if schedule.h_min < lo * (1 - 1e-9) or schedule.h_max > hi * (1 + 1e-9):
            print(f"warning: --schedule draws residence times in [{schedule.h_min:g}, {schedule.h_max:g}] s, "
                  f"outside the table's robust box [{lo:g}, {hi:g}] s (assumption A2): the paper's envelope "
                  "does not cover them; the exact bound still holds", file=sys.stderr)


def run(args: argparse.Namespace) -> int:
    system = load_system(args.config)
    table = GainTable.load(args.table, system=system)
    try:
        schedule = parse_schedule(args.schedule, N=system.N, dead_time=args.dead_time)
    except ScheduleError as err:
        raise InvalidArgument(f"--schedule {args.schedule}" + (f" with --dead-time {args.dead_time:g}"
                              if args.dead_time else "") + f": {err}") from None
    if not args.t_end > 0:
        raise InvalidArgument(f"--t-end must be > 0; got {args.t_end}")
    # the range policy (switchobs_core.ranges): magnitudes that the bounds square, a seed numpy takes
    check_range(args.e0, "e0", exc=InvalidArgument, flag="--e0")
    for flag, v, name in (("--noise", args.noise, "noise std"), ("--process-noise", args.process_noise, "noise std"),
                          ("--noise-max", args.noise_max, "noise.max")):
        if v is not None:
            check_range(v, name, exc=InvalidArgument, flag=flag)
    if not 0 <= args.seed < 2**63:
        raise InvalidArgument(f"--seed must be an integer in [0, 2^63); got {args.seed}")
    if args.plot is not None:
        check_output(args.plot, "--plot")     # before the simulation, not after it
    if args.plot is not None and args.plot.suffix.lower() not in PLOT_SUFFIXES:
        raise InvalidArgument(f"--plot {args.plot}: the figure's file name must end in one of "
                              f"{', '.join(PLOT_SUFFIXES)}")
    warn_a2(schedule, table)
    rng = np.random.default_rng(args.seed)
    x0 = rng.standard_normal(system.n)
    xhat0 = x0 + args.e0 * rng.standard_normal(system.n)
    res = simulate(system, table, schedule, x0, xhat0, args.t_end, rate=args.rate, hold=args.hold,
                   noise_std=args.noise, process_noise=args.process_noise, seed=args.seed,
                   noise_max=args.noise_max, progress=args.progress, bound=args.bound)
    summ = res.summary()
    summ["schedule"] = args.schedule
    bound, label, status = res.guarantee()
    summ["bounds"] = {"paper_bound": "alpha * sum z_i: the paper's claim (its proof has a gap)"
                      if res.family == "lmi" else "not applicable (the paper's envelope is for its LMI gains)",
                      "shown_bound": label, "shown_bound_status": status}
    if args.plot:
        summ["plot"] = str(plot_result(res, args.plot, f"{system.name}: {args.schedule}"
                                       + ("" if args.rate is None else f", {args.rate:g} Hz")))
    if args.json:
        print_json(summ)
        return 0
    print(f"simulate {system.name}, schedule {args.schedule}, t_end {args.t_end:g} s, "
          + ("continuous outputs" if args.rate is None else f"sampled at {args.rate:g} Hz")
          + (f", noise std {args.noise:g}" if args.noise else "")
          + (f" clipped to +-{args.noise_max:g}" if args.noise_max is not None else ""))
    en = res.error_norm
    rows = []
    for k, tc in enumerate(res.cycle_ends):
        j = res.at(tc)
        rows.append([k + 1, f"{res.t[j]:.3f}", f"{en[j]:.3e}",
                     "n/a" if bound is None else f"{bound[j]:.3e}",
                     f"{res.paper_bound[j]:.3e}" if res.family == "lmi" else "n/a"])
    if len(rows) > 12:
        rows = rows[:6] + [["...", "", "", "", ""]] + rows[-5:]
    print(fmt_table(["cycle end", "t [s]", "||x_tilde||", label, "paper bound (claim)"], rows))
    if res.family == "lmi" and len(res.cycle_ends) and res.at(res.cycle_ends[-1]) == len(res.t) - 1:
        print(f"(cycle {len(res.cycle_ends)} ends with the run: its paper bound is the value before the jump "
              "of the envelopes at a switch; the other rows show it after)")
    print(f"{label}: {status}")
    print(f"final ||x_tilde|| = {summ['final_error']:.3e} at t = {summ['t_end']:g} s "
          f"(||x_tilde(0)|| = {res.e0:.3e})")
    viol = summ["envelope_violations"]
    if viol is not None:
        print("paper's envelopes z_i exceeded at "
              + ", ".join(f"{v} of {len(res.t)} times (max ratio {r:.4g}) for i = {i + 1}"
                          for i, (v, r) in enumerate(zip(viol, summ["max_envelope_ratio"]))))
    if "plot" in summ:
        print(f"figure: {summ['plot']}")
    return 0
