"""``switchobs show``: print what a gain table holds (and check it against a system)."""

from __future__ import annotations

import argparse
from pathlib import Path

from ..model.scenarios import load_system
from ..model.schedule import Cycle
from ..table.gains import GainTable
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


def _margin_text(m) -> str:
    """The design's eta margin in words (``--margin``): ``eta = eta_min * 1.05`` or ``eta_min + 0.1``."""
    if isinstance(m, dict) and m.get("kind") == "relative":
        return f"{100 * float(m['value']):g} % (eta = eta_min * {1 + float(m['value']):g})"
    if isinstance(m, dict) and m.get("kind") == "absolute":
        return f"+{float(m['value']):g} (eta = eta_min + {float(m['value']):g})"
    return str(m)


def run(args: argparse.Namespace) -> int:
    system = load_system(args.system) if args.system else None
    table = GainTable.load(args.table, system=system)
    if table.family == "kalman":
        return _show_kalman(args, table, system)
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
        f"  software   switchobs {table.software_version}; eta margin {_margin_text(table.settings.get('margin'))}, "
        f"solver {table.settings.get('solver', '?')}"
    )
    rows = [[i + 1, c["r"], f"{c['mu']:.4f}", len(c["kappa_curve"]["eta"])] for i, c in enumerate(table.channels)]
    print(fmt_table(["channel", "r_i", "mu_i", "kappa samples"], rows))
    print()
    print_designs(table)
    return 0


def _kalman_rows(table: GainTable) -> list[dict]:
    """What a kalman table holds, read from the stored designs (no system needed)."""
    return [
        {
            "cycles": [Cycle(h, d.get("dead_time", 0.0)).label() for h in d["cycles"]],
            "rate_hz": d["rate"],
            "period_samples": len(d["periodic"]["channel"]),
            "startup_samples": len(d["startup"]["channel"]),
            "periods_to_converge": d["periods"],
            "spectral_radius": d["rho"],
            "norm": d["norm"],
            "noise": d["noise"],
        }
        for d in table.kalman
    ]


def _show_kalman(args: argparse.Namespace, table: GainTable, system: object) -> int:
    rows = _kalman_rows(table)
    if args.json:
        print_json({"system": table.system_name, "fingerprint": table.fingerprint, "family": "kalman",
                    "software_version": table.software_version, "kalman": rows,
                    "checked_against_system": system is not None})
        return 0
    print(f"gain table {args.table} (family kalman: offline periodic Kalman gains per sample phase)")
    print(f"  system     {table.system_name} (n = {table.n}, p = {list(table.p)}), "
          f"fingerprint {table.fingerprint[:16]}...")
    if system is not None:
        print(f"  checked    matches system '{table.system_name}'")
    print(f"  software   switchobs {table.software_version}")
    print(fmt_table(["cycle sequence", "rate", "period", "start-up", "rho (period)", "||period map||"],
                    [[", ".join(r["cycles"]), f"{r['rate_hz']:g} Hz", f"{r['period_samples']} samples",
                      f"{r['startup_samples']} samples", f"{r['spectral_radius']:.4g}", f"{r['norm']:.4g}"]
                     for r in rows]))
    return 0
