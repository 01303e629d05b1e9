#!/usr/bin/env python
"""Which clock rclpy's ``MessageInfo`` times are on, and how far the DDS reception precedes the
Python callback (a check for the live benchmarks' receivers, ``bench/_receipt.py``; not a test).

    python bench/receipt_clock.py [--messages 500] [--rate 50]

Two processes: a publisher sends ``--messages`` PoseStamped messages at ``--rate`` (reliable,
stamped with ``time.time_ns()`` just before ``publish``); this process receives them raw with
``MessageInfo`` (``switchobs_ros.executor.KeptWaitSetExecutor``) and keeps, per message,
``received_timestamp``, ``source_timestamp``, and ``time.time_ns()`` / ``time.monotonic_ns()``
in the callback. Printed: each difference's p50, p99 and range, so that a reception time on the
system clock shows as a small positive (Python - reception), one on the steady clock as a
difference of decades.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

TOPIC = "/receipt_clock/probe"


def publisher(n: int, rate: float) -> None:
    import rclpy
    from _receipt import RECEIVE
    from geometry_msgs.msg import PoseStamped
    rclpy.init()
    node = rclpy.create_node("receipt_clock_pub")
    pub = node.create_publisher(PoseStamped, TOPIC, RECEIVE)
    end = time.monotonic() + 60
    while pub.get_subscription_count() < 1 and time.monotonic() < end:
        time.sleep(0.01)
    time.sleep(0.3)
    m = PoseStamped()
    t_next = time.perf_counter()
    for _ in range(n):
        t_next += 1.0 / rate
        time.sleep(max(t_next - time.perf_counter(), 0.0))
        m.header.stamp.sec, m.header.stamp.nanosec = divmod(time.time_ns(), 1_000_000_000)
        pub.publish(m)
    time.sleep(0.5)
    node.destroy_node()
    rclpy.try_shutdown()


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--messages", type=int, default=500)
    ap.add_argument("--rate", type=float, default=50.0)
    ap.add_argument("--publisher", action="store_true", help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    if a.publisher:
        publisher(a.messages, a.rate)
        return 0
    import rclpy
    from _receipt import RECEIVE, pose_stamp
    from geometry_msgs.msg import PoseStamped

    from switchobs_ros.executor import KeptWaitSetExecutor
    from tools.domain import claim_domain, localhost_env
    from tools.launch import NodeProcess

    lease = claim_domain()
    os.environ.update(localhost_env(lease.domain_id))
    rows: list[tuple] = []
    rclpy.init()
    try:
        node = rclpy.create_node("receipt_clock_sub")
        node.create_subscription(PoseStamped, TOPIC, lambda raw, info: rows.append(
            (time.time_ns(), time.monotonic_ns(), info["received_timestamp"], info["source_timestamp"], raw)),
            RECEIVE, raw=True)
        ex = KeptWaitSetExecutor()
        ex.add_node(node)
        pub = NodeProcess("receipt_clock_pub", cmd=[sys.executable, __file__, "--publisher", "--messages",
                                                    str(a.messages), "--rate", str(a.rate)])
        try:
            while pub.alive():
                ex.spin_once(timeout_sec=0.05)
        finally:
            pub.stop()
        node.destroy_node()
    finally:
        rclpy.try_shutdown()
        lease.release()
    t = np.array([(w, mo, r, s, pose_stamp(raw)) for w, mo, r, s, raw in rows], dtype=np.int64).reshape(-1, 5)
    print(f"{len(t)}/{a.messages} messages at {a.rate:g} Hz; load average {os.getloadavg()[0]:.1f}.\n")
    print("| difference | p50 | p99 | min | max |")
    print("|---|---|---|---|---|")

    def row(name: str, d: np.ndarray, unit: float, u: str) -> None:
        q = np.percentile(d, [50, 99]) if d.size else [np.nan] * 2
        print(f"| {name} | {q[0] / unit:.4g} {u} | {q[1] / unit:.4g} {u} | {d.min() / unit:.4g} {u} "
              f"| {d.max() / unit:.4g} {u} |")
    row("Python time.time_ns() - received_timestamp", t[:, 0] - t[:, 2], 1e3, "us")
    row("Python time.monotonic_ns() - received_timestamp", t[:, 1] - t[:, 2], 1e9, "s")
    row("received_timestamp - source_timestamp", t[:, 2] - t[:, 3], 1e3, "us")
    row("source_timestamp - header stamp (time.time_ns() before publish)", t[:, 3] - t[:, 4], 1e3, "us")
    print(f"\nreceived_timestamp filled in {int((t[:, 2] != 0).sum())}/{len(t)}.")
    return 0


if __name__ == "__main__":
    sys.exit(main())
