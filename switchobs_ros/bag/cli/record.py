"""``switchobs_bag record``: subscribe to topics and write a bag (receive time on the node clock)."""

from __future__ import annotations

import argparse

from ..record import RecordConfig, record
from ._common import StopFlag, log, ros_node

__all__ = ["register", "run"]


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("record", help="subscribe to topics and write a bag (receive time on the node clock)")
    p.add_argument("out", help="new bag folder")
    p.add_argument("--topics", nargs="+", default=[], help="absolute topic names (default: the estimator's "
                   "inputs and outputs, /sim/truth, /diagnostics)")
    p.add_argument("--duration", type=float, default=0.0, help="stop after this many wall seconds")
    p.add_argument("--count", type=int, default=0, help="stop after this many messages")
    p.add_argument("--storage", choices=["mcap", "sqlite3"], default="mcap")
    p.add_argument("--wait-publishers", nargs="*", default=None, metavar="TOPIC",
                   help="before recording, wait for a publisher on these topics (none given: on every topic)")
    p.add_argument("--wait-timeout", type=float, default=30.0)

    p.set_defaults(func=run)


def run(a: argparse.Namespace, ros_argv: list[str]) -> int:
    stop = StopFlag()
    waited = None if a.wait_publishers is None else tuple(a.wait_publishers)
    cfg = RecordConfig(topics=tuple(a.topics), storage=a.storage, duration=a.duration, count=a.count,
                       wait_publishers=waited, wait_timeout=a.wait_timeout)
    with ros_node("switchobs_bag_record", ros_argv) as node:
        res = record(a.out, cfg, node=node, log=log, should_stop=stop)
    print(f"wrote {res['path']}: {res['messages']} messages"
          + (f" ({res['dropped_before_clock']} dropped before the first /clock)"
             if res["dropped_before_clock"] else ""), flush=True)
    return 0
