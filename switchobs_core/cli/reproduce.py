"""``switchobs reproduce``: the paper's table of decay rates and mu_i, side by side with ours,
and (with ``--figures``) the paper's figures as PNG.
"""

from __future__ import annotations

import argparse
import importlib
from pathlib import Path

from .. import paper
from ..design.lmi import Designer
from ..model.scenarios import paper_system
from ..model.schedule import Cycle
from ..sim.figures import eta_min_figures, kappa_figure
from ._common import fmt_table, print_json

__all__ = ["register", "run", "reproduce"]


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "reproduce",
        help="reproduce the paper's decay-rate table and figures",
        description="Print the paper's minimal and selected decay rates and mu_i next to ours.",
    )
    p.add_argument(
        "--delta", type=float, default=paper.DELTA, help=f"delta (default {paper.DELTA}, which reproduces the paper)"
    )
    p.add_argument("--figures", type=Path, metavar="DIR", help="write the paper's figures as PNG into DIR")
    p.add_argument("--json", action="store_true", help="print as JSON")
    p.add_argument("--progress", action=argparse.BooleanOptionalAction, default=None)
    p.set_defaults(func=run)


def reproduce(delta: float = paper.DELTA) -> tuple[Designer, dict]:
    """Compute our eta_min, the paper's factors with its selected rates, and mu_i."""
    system = paper_system()
    des = Designer(system, delta=delta)
    rows = []
    for (tau, s), emin_paper, eta_paper in paper.TABLE:
        c = Cycle.from_ts(tau, s)
        emin = des.eta_min(c)
        with_paper = des.design(c, eta=eta_paper)
        ours = des.design(c)
        rows.append(
            {
                "tau": tau,
                "s": s,
                "eta_min_paper": list(emin_paper),
                "eta_min_ours": list(emin),
                "eta_min_abs_diff": [abs(a - b) for a, b in zip(emin, emin_paper)],
                "eta_selected_paper": list(eta_paper),
                "f_with_paper_eta": list(with_paper.f),
                "eta_selected_ours": list(ours.eta),
                "f_with_our_eta": list(ours.f),
            }
        )
    mu = [ch.mu for ch in des.channels]
    return des, {"delta": delta, "mu_paper": list(paper.MU), "mu_ours": mu, "rows": rows}


def run(args: argparse.Namespace) -> int:
    des, res = reproduce(args.delta)
    figs: list[str] = []
    if args.figures:
        figs += [str(p) for p in eta_min_figures(des, args.figures, progress=args.progress)]
        figs.append(str(kappa_figure(des, args.figures, oracle=paper.kappa_closed_form)))
        try:
            errorfigs = importlib.import_module("switchobs_core.sim.errorfigs")
        except ModuleNotFoundError:
            errorfigs = None
        if errorfigs is not None:
            figs += [str(p) for p in errorfigs.write_error_figures(des.system, None, args.figures)]
    if args.json:
        res["figures"] = figs
        print_json(res)
        return 0
    f2 = lambda v: "(" + ", ".join(f"{x:.2f}" for x in v) + ")"
    f4 = lambda v: "(" + ", ".join(f"{x:.4f}" for x in v) + ")"
    print(f"The paper's decay rates (delta = {res['delta']:g}) side by side with ours\n")
    rows = [
        [
            f"({r['tau']:g} s, {r['s']:g})",
            f2(r["eta_min_paper"]),
            f4(r["eta_min_ours"]),
            f"{max(r['eta_min_abs_diff']):.4f}",
            f2(r["eta_selected_paper"]),
            f4(r["f_with_paper_eta"]),
            f4(r["eta_selected_ours"]),
            f4(r["f_with_our_eta"]),
        ]
        for r in res["rows"]
    ]
    print(
        fmt_table(
            [
                "(tau, s)",
                "eta_min paper",
                "eta_min ours",
                "max |diff|",
                "eta paper",
                "f_ii at paper eta",
                "eta ours (+5%)",
                "f_ii at our eta",
            ],
            rows,
        )
    )
    print()
    print(
        fmt_table(
            ["", "paper", "ours"],
            [[f"mu_{i + 1}", f"{res['mu_paper'][i]:.4f}", f"{res['mu_ours'][i]:.4f}"] for i in range(2)],
        )
    )
    print(
        "\nf_ii is the paper's cycle factor (<= delta is the paper's condition, not a guarantee;"
        " see `switchobs certify`). The first row is the paper's periodic case (Sec. subsec:sim_gain)."
    )
    for f in figs:
        print(f"wrote {f}")
    return 0
