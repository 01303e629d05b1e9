"""``switchobs certify``: the paper's certificate and a sound one, side by side."""

from __future__ import annotations

import argparse
from pathlib import Path

from ..certificate import certify_table, format_report
from ..exceptions import InvalidArgument
from ..model.scenarios import load_system
from ..table.gains import GainTable
from ._common import parse_ts, print_json

__all__ = ["register", "run"]


#: Most cycles ``--ratio-cycles`` samples (at 2 ms each, 1000 cycles of 2 s are 1e6 samples).
MAX_RATIO_CYCLES = 1000

def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "certify",
        help="print the paper's certificate and the sound (verified) one side by side",
        description=(
            "For every design of a gain table: the paper's cycle factors f_ii (its claim; the proof "
            "has a gap), the exact cycle transition's spectral radius and norm (verified), and the "
            "worst-case ratio by which the paper's envelopes z_i are exceeded. With --sequence: a "
            "common quadratic Lyapunov function for those cycle types (any order). For a robust "
            "design: a certificate over the whole residence-time box."
        ),
    )
    p.add_argument("table", type=Path, help="gain table file")
    p.add_argument("--system", metavar="CONFIG",
                   help="scenario name or YAML file (default: the table's system name, if built in)")
    p.add_argument("--sequence", nargs="+", type=parse_ts, metavar="TAU,S",
                   help="cycle types to certify for any order, e.g. 4,0.5 3,0.6 2,0.4")
    p.add_argument("--ratio-cycles", type=int, default=5, help="cycles over which the envelope ratio is maximised")
    p.add_argument("--no-box", action="store_true", help="skip the robust box certificate")
    p.add_argument("--json", action="store_true", help="print as JSON")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    if args.system:
        system = load_system(args.system)
    else:
        table0 = GainTable.load(args.table)
        try:
            system = load_system(table0.system_name)
        except Exception:
            raise InvalidArgument(
                f"cannot load the table's system '{table0.system_name}'; pass --system CONFIG") from None
    table = GainTable.load(args.table, system=system)
    if not 1 <= args.ratio_cycles <= MAX_RATIO_CYCLES:
        raise InvalidArgument(f"--ratio-cycles must be in [1, {MAX_RATIO_CYCLES}] (a sampled run over that many "
                              f"cycles); got {args.ratio_cycles}")
    rep = certify_table(system, table, sequence=args.sequence, ratio_cycles=args.ratio_cycles,
                        box=not args.no_box)
    if args.json:
        print_json(rep.to_dict())
        return 0
    print(f"certify {args.table} for system '{system.name}' (alpha = {system.alpha:.4f})")
    print(format_report(rep))
    return 0
