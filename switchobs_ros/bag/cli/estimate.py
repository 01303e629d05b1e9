"""``switchobs_bag estimate``: the estimator's pipeline over a bag, offline; a bag and/or a CSV out."""

from __future__ import annotations

import argparse
import json
import sys

from switchobs_core.files import check_output
from switchobs_core.loading import parse_yaml

from ...config import params_from_file
from ..estimate import OUTPUTS, estimate, nothing_estimated
from ..io import BagError

__all__ = ["DEFAULT_OUTPUTS", "STRICT_EXIT", "register", "run", "params_of", "outputs_of"]

#: Exit code of ``--strict`` when valid measurements went unanswered.
STRICT_EXIT = 4
#: What ``--outputs`` writes unless told: every output but ``<node>/covariance``, whose numbers the typed
#: ``<node>/state_estimate`` carries too (at n = 132 each copy is 139 KB an estimate, 7 MB a second at 50 Hz).
DEFAULT_OUTPUTS = ("envelope", "odometry", "typed")


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("estimate", help="run the estimator pipeline over a bag, offline; write a bag and CSV")
    p.add_argument("bag")
    p.add_argument("-o", "--out", help="new bag folder for the estimates (and the copied inputs)")
    p.add_argument("--csv", help="CSV file of the estimates")
    p.add_argument("--storage", choices=["mcap", "sqlite3"], default=None, help="default: the input bag's")
    p.add_argument("--estimates-only", action="store_true", help="do not copy the input topics")
    p.add_argument("--outputs", default=",".join(DEFAULT_OUTPUTS), metavar="LIST",
                   help=f"outputs written to the bag besides <node>/state, comma-separated from {', '.join(OUTPUTS)}, "
                        f"'all' or 'none' (default {','.join(DEFAULT_OUTPUTS)}: the covariance is in the typed "
                        "state_estimate; add covariance for <node>/covariance as well)")
    p.add_argument("--params-file", action="append", default=[], help="estimator params file (ROS 2 YAML)")
    p.add_argument("-p", "--param", action="append", default=[], metavar="NAME:=VALUE")
    p.add_argument("--gain-table", help="shortcut for -p gain_table:=FILE")
    p.add_argument("--system", help="shortcut for -p system:=NAME_OR_FILE (a built-in scenario or a system YAML, "
                                    "whose inputs: section names the topics to read)")
    p.add_argument("--node", default="/estimator", help="namespace of the output topics (default /estimator)")
    p.add_argument("--json", action="store_true")
    p.add_argument("--progress", action=argparse.BooleanOptionalAction, default=None,
                   help="progress bar on stderr (default: on a terminal, off with --json)")
    p.add_argument("--strict", action="store_true",
                   help=f"exit {STRICT_EXIT} when any valid (accepted) measurement got no estimate (the summary "
                        "names the reasons)")

    p.set_defaults(func=run)


def params_of(a: argparse.Namespace) -> dict:
    """The estimator's parameter values from ``--params-file``, ``-p NAME:=VALUE`` and ``--gain-table``."""
    over = {}
    for item in a.param:
        name, sep, val = item.partition(":=")
        if not sep:
            raise BagError(f"-p {item}: expected NAME:=VALUE")
        over[name] = parse_yaml(val, exc=BagError, source=f"-p {name}") if val != "" else ""
    if a.gain_table:
        over["gain_table"] = a.gain_table
    if a.system:
        over["system"] = a.system
    return params_from_file(a.params_file, over)


def outputs_of(text: str) -> tuple[str, ...]:
    """The outputs an ``--outputs`` value names (``all``: every one; ``none``: only ``<node>/state``)."""
    names = [x.strip() for x in text.split(",") if x.strip()]
    if names == ["all"]:
        return OUTPUTS
    if names == ["none"]:
        return ()
    unknown = [x for x in names if x not in OUTPUTS]
    if unknown:
        raise BagError(f"--outputs: unknown output {', '.join(unknown)} (known: {', '.join(OUTPUTS)}, all, none)")
    return tuple(names)


def run(a: argparse.Namespace, ros_argv: list[str]) -> int:
    if not a.out and not a.csv:
        raise BagError("give -o OUT (a new bag) and/or --csv FILE")
    if a.csv:
        check_output(a.csv, "--csv", exc=BagError)       # before the run, not after it
    outputs = outputs_of(a.outputs)
    res = estimate(a.bag, params_of(a), out=a.out, csv=a.csv, storage=a.storage, inputs=not a.estimates_only,
                   node=a.node, progress=False if a.json else a.progress, keep=False, outputs=outputs)
    if res.uncovered:
        print(f"switchobs_bag: warning: {res.uncovered_warning}", file=sys.stderr)
    if not res.count:
        raise BagError(f"bag {a.bag}: no estimate: {nothing_estimated(res)}")
    rate = res.messages_in / res.seconds if res.seconds > 0 else float("inf")
    info = {"estimates": res.count, "messages": res.messages_in, "inputs": res.inputs,
            "seconds": res.seconds, "messages_per_s": rate, "updates": res.updates,
            "partial_updates": res.partial_updates, "rejected": res.rejected, "unanswered": res.unanswered,
            "inconsistent": res.inconsistent, "reattributed": res.reattributed, "bounds_valid": res.bound_valid,
            "uncovered_channels": list(res.uncovered), "unordered": res.unordered,
            "whole_order": res.whole_order, "out": res.out, "csv": res.csv}
    code = STRICT_EXIT if a.strict and res.unanswered else 0
    if a.json:
        print(json.dumps(info))
    else:
        print(f"{res.count} estimates from {res.messages_in} messages in {res.seconds:.3f} s "
              f"({rate:,.0f} messages/s); partial updates {res.partial_updates}; rejected "
              f"{sum(res.rejected.values())} {res.rejected or ''}".rstrip())
        if res.unanswered:
            print(f"valid measurements without an estimate: {sum(res.unanswered.values())} {res.unanswered}")
        if res.unordered:
            print(f"samples whose channel the recording cannot tell: {res.unordered} (log times that tie or contradict "
                  f"the stamps around a channel change; rejected as ambiguous_channel, never guessed)")
        if res.whole_order:
            print(f"the recording was ordered whole (read twice): {res.whole_order}")
        if res.recertifications or res.bias_alarms or res.model_failures:
            print(f"re-certifications {res.recertifications} (latest: {res.recertified or 'none'}); bias alarms "
                  f"{res.bias_alarms}; model failures (gate) {res.model_failures}")
        if not res.bound_valid:
            print(f"bounds withdrawn: {res.bound_invalid_why}")
        for what in ("out", "csv"):
            if info[what]:
                print(f"wrote {info[what]}")
    if code:
        print(f"switchobs_bag: error: --strict: {sum(res.unanswered.values())} valid measurements got no estimate "
              f"({', '.join(f'{k} {v}' for k, v in res.unanswered.items())})", file=sys.stderr)
    return code
