"""``switchobs_bag info``: topics, types, counts and span of a bag."""

from __future__ import annotations

import argparse

from ..io import BagIn

__all__ = ["register", "run"]


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("info", help="topics, types, counts and span of a bag")
    p.add_argument("bag")
    p.set_defaults(func=run)


def run(a: argparse.Namespace, ros_argv: list[str]) -> int:
    with BagIn(a.bag) as bag:
        msgs = bag.messages()
        span = (msgs[-1].log_ns - msgs[0].log_ns) * 1e-9 if msgs else 0.0
        print(f"{bag.path} ({bag.storage}): {bag.message_count} messages, {span:.3f} s")
        for t, ty in sorted(bag.topics.items()):
            print(f"  {t:36s} {ty:40s} {bag.counts[t]}")
    return 0
