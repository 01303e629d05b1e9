"""``switchobs design``: design a gain table for a system (a YAML file or a built-in scenario)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from ..design.kalman import design_kalman
from ..design.lmi import Designer, Margin
from ..exceptions import InvalidArgument
from ..families import DESIGNABLE, family_entry
from ..files import check_output
from ..loading import MAX_FILE_BYTES
from ..model.scenarios import load_disturbance, load_noise, load_system
from ..model.schedule import Cycle
from ..model.system import LTISystem
from ..ranges import MAX_CYCLES, check_count
from ..table.gains import CycleDesign, GainTable, kalman_table
from ..table.io import save_loadable
from ._common import add_dead_time, fmt_table, parse_floats, parse_h, parse_pair, parse_ts, print_json, with_dead_time

__all__ = ["register", "run", "run_kalman", "design_rows", "table_summary", "kalman_summary"]

#: Gain families ``--gains`` designs (the registry's stored families; ``kalman-online`` needs no table).
FAMILIES = DESIGNABLE


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "design",
        help="design gains for cycles and/or a residence-time box and write a gain table",
        description="Design switched-observer gains offline (the paper's Section 7) and write a gain table file.",
        epilog="example: switchobs design paper --cycle 2,0.6 --delta 0.99 -o gains.json",
    )
    p.add_argument("config", help="built-in scenario name (paper, camera_agents) or a system YAML file")
    p.add_argument(
        "--cycle",
        type=parse_ts,
        action="append",
        default=[],
        metavar="TAU,S",
        help="two-channel cycle: length TAU s, channel 1 active for S*TAU s (repeatable)",
    )
    p.add_argument(
        "--cycle-h",
        type=parse_h,
        action="append",
        default=[],
        metavar="H1,...,HN",
        help="N-channel cycle by active times (repeatable)",
    )
    p.add_argument(
        "--robust",
        type=parse_pair,
        metavar="HMIN,HMAX",
        help="also design one gain set for every schedule with residence times in [HMIN, HMAX]",
    )
    add_dead_time(p)
    p.add_argument("--delta", type=float, default=0.99, help="cycle contraction target delta in (0, 1) (default 0.99)")
    p.add_argument(
        "--margin",
        type=Margin.parse,
        default=Margin(),
        metavar="M",
        help="eta = eta_min + M (absolute, e.g. 0.1) or eta_min*(1+M) (relative, e.g. 5%%); default 5%%",
    )
    p.add_argument(
        "--eta",
        type=_parse_eta,
        action="append",
        default=[],
        metavar="E1,...,EN",
        help="decay rates set explicitly, one per channel (instead of eta_min + margin). Given once, it applies "
        "to every cycle; given k times, the j-th --eta applies to the j-th cycle (--cycle flags first, then "
        "--cycle-h). Gains are verified; f_ii > delta is reported, not refused",
    )
    p.add_argument(
        "--gains",
        choices=FAMILIES,
        default="lmi",
        help="gain family: lmi (the paper's LMI gains, per cycle) or kalman (offline periodic Kalman gains per "
        "sample phase at --rate; several --cycle flags form one repeating sequence, in that order)",
    )
    p.add_argument("--rate", type=float, metavar="HZ", help="nominal sample rate in Hz (required with --gains kalman)")
    p.add_argument(
        "--meas-noise",
        type=float,
        metavar="STD",
        help="measurement noise std on every output row (overrides the system's noise: section; default 1 mm)",
    )
    p.add_argument(
        "--process-noise",
        type=float,
        metavar="Q",
        help="process noise q on every state: continuous white noise of intensity Q_c = q^2 I, discretised by "
        "van Loan (the same meaning as `switchobs_bag generate --process-noise`)",
    )
    p.add_argument("-o", "--output", required=True, type=Path,
                   help="gain table file to write: JSON, or the binary container for a name ending in .npz (a JSON "
                        "name for a table over 16 MiB is written as .npz beside it, with a note)")
    p.add_argument("--json", action="store_true", help="print the summary as JSON")
    p.add_argument(
        "--progress", action=argparse.BooleanOptionalAction, default=None, help="progress bar (default: on a terminal)"
    )
    p.set_defaults(func=run)


def design_rows(designs: list[CycleDesign]) -> list[list[str]]:
    rows = []
    for d in designs:
        rows.append(
            [
                d.label(),
                ", ".join("-" if e is None else f"{e:.4f}" for e in d.eta_min),
                ", ".join(f"{e:.4f}" for e in d.eta),
                ", ".join(f"{k:.4f}" for k in d.kappa),
                ", ".join(f"{f:.4f}" for f in d.f),
                "yes" if d.certified else "NO",
            ]
        )
    return rows


def table_summary(table: GainTable) -> dict:
    def one(d: CycleDesign) -> dict:
        return {
            "label": d.label(),
            "kind": d.kind,
            "cycle": None if d.cycle is None else d.cycle.to_dict(),
            "h_bounds": d.h_bounds,
            "eta_min": d.eta_min,
            "eta": d.eta,
            "kappa": d.kappa,
            "mu": d.mu,
            "f": d.f,
            "delta": d.delta,
            "paper_condition_holds": d.certified,
        }

    return {
        "system": table.system_name,
        "fingerprint": table.fingerprint,
        "n": table.n,
        "p": table.p,
        "delta": table.delta,
        "settings": table.settings,
        "software_version": table.software_version,
        "channels": [
            {"channel": i + 1, "r": c["r"], "mu": c["mu"], "kappa_samples": len(c["kappa_curve"]["eta"])}
            for i, c in enumerate(table.channels)
        ],
        "designs": [one(d) for d in table.designs],
        "robust": None if table.robust is None else one(table.robust),
    }


def print_designs(table: GainTable) -> None:
    header = ["design", "eta_min", "eta", "kappa", "f_ii (paper)", "f_ii <= delta"]
    designs = table.designs + ([table.robust] if table.robust is not None else [])
    print(fmt_table(header, design_rows(designs)))
    print(
        f"delta = {', '.join(f'{x:g}' for x in table.delta)}; f_ii = kappa_i exp(mu_i (tau - h_i) - eta_i h_i) "
        "is the paper's cycle factor (its envelope is not a guarantee: run `switchobs certify` for the sound one)"
    )
    if any(d.cycle is not None and d.cycle.dead_time for d in designs):
        print("with a dead time d the blind interval is inactive time: f_ii = kappa_i exp(mu_i (tau - h_i + d) - "
              "eta_i (h_i - d)), and the gains are not applied while blind")


def kalman_summary(table: GainTable, system: LTISystem) -> dict:
    """JSON summary of a kalman table: per design the rate, cycles, noise, period and certificate."""
    out = []
    for d in table.kalman:
        kd = table.kalman_design([Cycle(h, d.get("dead_time", 0.0)) for h in d["cycles"]], system)
        out.append({
            "cycles": [c.to_dict() for c in kd.cycles],
            "rate_hz": kd.rate,
            "noise": kd.noise.to_dict(),
            "period_samples": kd.pattern.K,
            "startup_samples": len(kd.startup),
            "periods_to_converge": kd.periods,
            "period_error_transition": {"spectral_radius": kd.rho, "norm": kd.norm},
        })
    return {"system": table.system_name, "fingerprint": table.fingerprint, "family": table.family, "kalman": out}


def run_kalman(args: argparse.Namespace, system: LTISystem, cycles: list[Cycle]) -> int:
    """``--gains kalman``: one offline periodic Kalman design for the cycle sequence."""
    if args.rate is None:
        raise InvalidArgument("--gains kalman needs the nominal sample rate: add --rate HZ")
    if not cycles:
        raise InvalidArgument("--gains kalman needs the schedule: give --cycle TAU,S (or --cycle-h) once for a "
                              "periodic schedule, several times for a repeating sequence")
    if args.robust is not None:
        raise InvalidArgument("--robust designs LMI gains for any schedule in a box; Kalman gains need a known "
                              "schedule (without one the estimator runs the Riccati recursion online: mode robust)")
    noise = load_noise(args.config, system, meas_std=args.meas_noise, process_q=args.process_noise,
                       disturbance=load_disturbance(args.config, system))
    kd = design_kalman(system, cycles, args.rate, noise, progress=args.progress)
    table = kalman_table(system, [kd])
    args.output = save(table, args.output)
    if args.json:
        out = kalman_summary(table, system)
        out["output"] = str(args.output)
        print_json(out)
        return 0
    print(system.describe())
    print()
    print(noise.describe())
    print(kd.describe())
    print("sound certificate of the periodic closed loop: the period's error transition has the spectral radius "
          "and norm above (< 1: the error contracts every period, for noise-free samples on the schedule)")
    print(f"wrote {args.output}")
    return 0


def save(table: Any, path: Path) -> Path:
    """Write the table where ``-o`` says, or, for a JSON name whose JSON loading would refuse (over
    16 MiB: a Kalman table of many phases), as ``.npz`` beside it, saying so in one line on stderr;
    the path written."""
    written, size = save_loadable(table, path)
    if size is not None:
        limit = MAX_FILE_BYTES // 2 ** 20
        print(f"note: the table's JSON would be at least {size / 2 ** 20:.0f} MiB, above the {limit} MiB a JSON gain "
              f"table may have: wrote the binary container {written} instead (switchobs show, simulate and the nodes "
              "load it; name the output .npz to choose it)", file=sys.stderr)
    return written


def run(args: argparse.Namespace) -> int:
    check_output(args.output, "-o")           # before the design, not after it
    check_count(len(args.cycle) + len(args.cycle_h), "--cycle/--cycle-h", MAX_CYCLES)
    system = load_system(args.config)
    cycles = with_dead_time(list(args.cycle) + list(args.cycle_h), args.dead_time)
    if args.dead_time and args.robust is not None:
        raise InvalidArgument("--dead-time with --robust is not supported: a robust design has no schedule to "
                              "place the blind intervals in; design the cycles you run with --cycle")
    if family_entry(args.gains).rate:       # a design at a nominal rate under a noise model
        return run_kalman(args, system, cycles)
    if args.rate is not None or args.meas_noise is not None or args.process_noise is not None:
        raise InvalidArgument("--rate, --meas-noise and --process-noise belong to --gains kalman "
                              "(the paper's LMI gains do not depend on them)")
    if not cycles and args.robust is None:
        raise InvalidArgument("nothing to design: give the schedule with --cycle TAU,S (or --cycle-h H1,...,HN), "
                              "repeated for a sequence, and/or a residence-time box with --robust HMIN,HMAX")
    designer = Designer(system, delta=args.delta, margin=args.margin)
    etas = _etas_for(args.eta, cycles)
    table = designer.table(cycles, robust=args.robust, etas=etas, progress=args.progress)
    args.output = save(table, args.output)
    if args.json:
        out = table_summary(table)
        out["output"] = str(args.output)
        print_json(out)
        return 0
    print(system.describe())
    print()
    print_designs(table)
    for d in table.designs:
        for i, (f, dl) in enumerate(zip(d.f, d.delta)):
            if f > dl:
                print(
                    f"{d.label()}, channel {i + 1}: f = {f:.4f} > delta = {dl:g}: the paper's condition fails "
                    "for this rate (choose a larger eta)"
                )
    print(f"wrote {args.output}")
    return 0


def _etas_for(etas: list[tuple[float, ...]], cycles: list) -> list | None:
    """Explicit rates per cycle from the repeated ``--eta`` flags (rule in the flag's help)."""
    if not etas:
        return None
    if len(etas) == 1:
        return [etas[0]] * len(cycles)
    if len(etas) != len(cycles):
        raise InvalidArgument(
            f"--eta was given {len(etas)} times for {len(cycles)} cycles: give it once (for every cycle) "
            "or once per cycle, in the order of the --cycle and then --cycle-h flags"
        )
    return list(etas)


def _parse_eta(text: str) -> tuple[float, ...]:
    """``E1,...,EN`` -> positive rates (argparse type)."""
    try:
        vals = tuple(parse_floats(text, "--eta"))
    except InvalidArgument as err:
        raise argparse.ArgumentTypeError(str(err)) from None
    if any(v <= 0 for v in vals):
        raise argparse.ArgumentTypeError(f"--eta rates must be > 0; got {text!r}")
    return vals
