"""``switchobs_bag report``: plots and a summary from a bag with estimates (and truth)."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

import msg_bridge as mb
from switchobs_core.files import check_output, write_with
from switchobs_ros.core_config import load_system_param

from ..io import BagError
from ..report import load_report, plot_report, summary_table

__all__ = ["GUARANTEE_FAILED", "register", "run"]

#: Exit code when a published guaranteed (noise) bound is below the error in the bag.
GUARANTEE_FAILED = 3


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("report", help="plots and a summary from a bag with estimates (and truth)")
    p.add_argument("bag")
    p.add_argument("-o", "--out", default="report.png", help="PNG file (default report.png)")
    p.add_argument("--summary", help="also write the summary (Markdown) to this file")
    p.add_argument("--node", default="/estimator")
    p.add_argument("--system", help="the estimated system (scenario name or YAML, as the node's parameter): its "
                   "input specification says where the channel signal is (default: /camera/active_channel)")
    p.add_argument("--inputs", default="", help="a YAML file with an inputs: section overriding the system's")
    p.add_argument("--title", default="")
    p.add_argument("--json", action="store_true")

    p.set_defaults(func=run)


def fin(v: float) -> float | None:
    """A number for ``--json``: JSON has no NaN or Infinity, so a non-finite value (no truth, an
    envelope that overflowed) is ``null``; the output is always valid JSON (``allow_nan=False``)."""
    return float(v) if np.isfinite(v) else None


def run(a: argparse.Namespace, ros_argv: list[str]) -> int:
    check_output(a.out, "-o", exc=BagError)          # before reading the bag
    if a.summary:
        check_output(a.summary, "--summary", exc=BagError)
    inputs = None
    if a.system:
        system = load_system_param(a.system)
        inputs = mb.load_inputs(a.system, system, override=a.inputs)
    elif a.inputs:
        raise BagError("--inputs needs --system (the specification is checked against the system)")
    rep = load_report(a.bag, a.node, inputs)
    plot_report(rep, a.out, a.title)
    text = summary_table(rep)
    if a.summary:
        write_with(a.summary, "--summary", lambda q: Path(q).write_text(text + "\n"), exc=BagError)
    if a.json:
        print(json.dumps({"passes": [{"estimates": len(p.t), "initial_error": fin(p.e_first),
                                      "final_error": fin(p.e_final),
                                      "final_exact_bound": fin(p.exact[-1]),
                                      "exact_bound_violations": p.violations(p.exact),
                                      "final_noise_bound": None if p.noise is None else fin(p.noise[-1]),
                                      "noise_bound_violations": p.violations(p.noise),
                                      "final_paper_bound": fin(p.paper[-1]),
                                      "cycles": None if p.cycle_ends is None else len(p.cycle_ends),
                                      "contraction": [fin(c) for c in p.contraction]} for p in rep.passes],
                          "rejected": rep.rejected, "png": a.out}, allow_nan=False))
    else:
        print(text)
        print(f"wrote {a.out}" + (f" and {a.summary}" if a.summary else ""))
    # a declared noise bound is a guarantee: an error above it means the model or the declared
    # bound does not hold for this recording (the estimator's consistency test withdraws it when
    # the data show it; what was published before that is counted here)
    false = sum(p.violations(p.noise) or 0 for p in rep.passes if p.noise is not None)
    if false:
        print(f"switchobs_bag: error: {false} published estimates are above the published noise bound (a "
              "guarantee under the declared noise.max): the model or the declared bound does not hold for this "
              "recording", file=sys.stderr)
        return GUARANTEE_FAILED
    return 0
