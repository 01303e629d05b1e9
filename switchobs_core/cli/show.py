"""``switchobs show``: print what a gain table holds (and check it against a system)."""

from __future__ import annotations

import argparse
from pathlib import Path

from ..gains import GainTable
from ..scenarios import load_system
from ._common import fmt_table, print_json
from .design import print_designs, table_summary

__all__ = ["register", "run"]


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "show",
        help="print a gain table's contents and check its integrity",
        description="Print a gain table; with --system, also check that it was made for that system.",
    )
    p.add_argument("table", type=Path, help="gain table file")
    p.add_argument("--system", metavar="CONFIG", help="scenario name or YAML file to check the table against")
    p.add_argument("--json", action="store_true", help="print as JSON")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    system = load_system(args.system) if args.system else None
    table = GainTable.load(args.table, system=system)
    if args.json:
        out = table_summary(table)
        out["checked_against_system"] = system is not None
        print_json(out)
        return 0
    print(f"gain table {args.table}")
    print(
        f"  system     {table.system_name} (n = {table.n}, p = {list(table.p)}), "
        f"fingerprint {table.fingerprint[:16]}..."
    )
    if system is not None:
        print(f"  checked    matches system '{system.name}'")
    print(
        f"  software   switchobs {table.software_version}; margin {table.settings['margin']}, "
        f"solver {table.settings['solver']}"
    )
    rows = [[i + 1, c["r"], f"{c['mu']:.4f}", len(c["kappa_curve"]["eta"])] for i, c in enumerate(table.channels)]
    print(fmt_table(["channel", "r_i", "mu_i", "kappa samples"], rows))
    print()
    print_designs(table)
    return 0
