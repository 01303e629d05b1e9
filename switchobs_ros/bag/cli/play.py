"""``switchobs_bag play``: publish a bag live, with ``/clock``."""

from __future__ import annotations

import argparse

from ..play import PlayConfig, play
from ._common import StopFlag, log, ros_node

__all__ = ["register", "run"]


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("play", help="publish a bag live, with /clock")
    p.add_argument("bag")
    p.add_argument("--rate", type=float, default=1.0, help="speed factor (default 1: recorded timing)")
    p.add_argument("--loop", action="store_true", help="play again and again until stopped")
    p.add_argument("--loops", type=int, default=1, help="number of passes (default 1)")
    p.add_argument("--no-clock", action="store_true", help="do not publish /clock (play the bag's own, if any)")
    p.add_argument("--topics", nargs="+", default=[], help="only these topics")
    p.add_argument("--all-topics", action="store_true",
                   help="also the estimator's outputs and /diagnostics (skipped by default)")
    p.add_argument("--no-wait", action="store_true", help="start at once, without waiting for subscribers")
    p.add_argument("--wait-node", default="estimator",
                   help="wait until this node subscribes to the inputs and /clock ('' = any node)")
    p.add_argument("--wait-timeout", type=float, default=30.0)
    p.add_argument("--settle", type=float, default=0.5, help="seconds between the match and the first message")
    p.add_argument("--channel-lead", type=float, default=0.005,
                   help="seconds to wait after a channel change before the next message (default 0.005)")
    p.add_argument("--loop-pause", type=float, default=0.2, help="seconds after the /clock jump of a new pass")

    p.set_defaults(func=run)


def run(a: argparse.Namespace, ros_argv: list[str]) -> int:
    stop = StopFlag()
    cfg = PlayConfig(rate=a.rate, loops=0 if a.loop else a.loops, clock=not a.no_clock,
                     topics=tuple(a.topics), all_topics=a.all_topics, wait=not a.no_wait,
                     wait_node=a.wait_node, wait_timeout=a.wait_timeout, settle=a.settle,
                     channel_lead=a.channel_lead, loop_pause=a.loop_pause)
    with ros_node("switchobs_bag_play", ros_argv) as node:
        res = play(a.bag, cfg, node=node, log=log, should_stop=stop)
    print(f"played {res['published']} messages in {res['passes']} pass(es); "
          f"latest message {res['max_late_s'] * 1e3:.1f} ms behind its time", flush=True)
    return 0
