#!/usr/bin/env python
"""In-process cost of an executor per callback: rclpy's SingleThreadedExecutor against
switchobs_ros.executor.KeptWaitSetExecutor, interleaved rounds in one process (not a test).

    python bench/bench_executor.py [--messages 3000] [--rounds 5] [--before /path/to/other/checkout]

A node with the estimator's entity count (three input subscriptions, ``~/set_state``, two timers,
``~/reset``, the parameter and type-description services rclpy gives every node) receives
``--messages`` messages per round, one at a time: a thread publishes a message on one of the
three input topics (in turn) 1 ms after it is told to, while this thread spins until its callback
ran; this thread's CPU time (``time.thread_time``) per message, and the executor's waits per message (the kept executor
counts them; rclpy's: one wait per ``_wait_for_ready_callbacks`` pass, counted by wrapping the rcl
wait set's ``wait``). Medians over the rounds, and the ratio. ``--before DIR`` adds ``kept_before``:
the ``KeptWaitSetExecutor`` of another checkout's ``switchobs_ros/executor.py``, loaded beside this
one, in the same interleaved rounds. ``--idle K`` adds, for each kept executor, the CPU time of one
wait with nothing ready (``K`` zero-timeout waits per round, the estimator's entities and two publishers
with their QoS event handlers): the executor's own Python per wait and rcl's wait, no callback.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import threading
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import rclpy
from rclpy.executors import SingleThreadedExecutor
from std_msgs.msg import Float64MultiArray
from std_srvs.srv import Trigger

from switchobs_ros import qos
from switchobs_ros.executor import KeptWaitSetExecutor


def node_like_the_estimator(name: str, got: list):
    node = rclpy.create_node(name)
    for t in ("a", "b", "c", "set_state"):
        node.create_subscription(Float64MultiArray, f"/bench_exec/{t}", lambda m, i: got.append(1),
                                 qos.CHANNEL_SUB)
    node.create_timer(1.0, lambda: None)
    node.create_timer(0.0125, lambda: None).cancel()
    node.create_service(Trigger, "~/reset", lambda q, r: r)
    return node


def executor_from(tree: Path) -> type:
    """``KeptWaitSetExecutor`` of the checkout ``tree`` (its ``switchobs_ros/executor.py`` loaded as
    a module of its own)."""
    import importlib.util
    spec = importlib.util.spec_from_file_location("executor_before", tree / "switchobs_ros" / "executor.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod.KeptWaitSetExecutor


KEPT = {"kept": KeptWaitSetExecutor}


def one_round(kind: str, n: int) -> tuple[float, float]:
    got: list = []
    node = node_like_the_estimator(f"bench_exec_{kind}", got)
    pub_node = rclpy.create_node(f"bench_exec_pub_{kind}")
    pubs = [pub_node.create_publisher(Float64MultiArray, f"/bench_exec/{t}", qos.OUTPUT) for t in "abc"]
    ex = KEPT[kind]() if kind in KEPT else SingleThreadedExecutor()
    ex.add_node(node)
    waits = [0]
    if kind == "rclpy":         # count rclpy's waits: wrap the wait set class its executor builds
        import rclpy.executors as rex
        real = rex._rclpy.WaitSet

        class Counting:
            def __init__(self, *a):
                self._ws = real(*a)

            def wait(self, t):
                waits[0] += 1
                return self._ws.wait(t)

            def __getattr__(self, k):
                return getattr(self._ws, k)
        rex._rclpy.WaitSet = Counting
    end = time.monotonic() + 20
    while any(p.get_subscription_count() == 0 for p in pubs) and time.monotonic() < end:
        ex.spin_once(timeout_sec=0.05)
    for _ in range(20):
        ex.spin_once(timeout_sec=0.01)
    got.clear()
    w0 = ex.waits if kind in KEPT else waits[0]
    msg = Float64MultiArray(data=[0.0] * 8)
    go, stop = threading.Event(), []

    def sender() -> None:         # publishes 1 ms after it is told to: the executor waits meanwhile
        k = 0
        while True:
            go.wait()
            go.clear()
            if stop:
                return
            time.sleep(0.001)
            pubs[k % 3].publish(msg)
            k += 1
    th = threading.Thread(target=sender)
    th.start()
    cpu = 0.0
    for k in range(n):
        go.set()
        c0 = time.thread_time()
        while len(got) <= k:
            ex.spin_once(timeout_sec=1.0)
        cpu += time.thread_time() - c0
    stop.append(1)
    go.set()
    th.join()
    w = (ex.waits if kind in KEPT else waits[0]) - w0
    if kind == "rclpy":
        import rclpy.executors as rex
        rex._rclpy.WaitSet = real
    ex.shutdown()
    node.destroy_node()
    pub_node.destroy_node()
    return cpu / n * 1e6, w / n


def idle_round(kind: str, k: int) -> float:
    """CPU time (us) of one zero-timeout wait of executor ``kind`` with nothing ready (``k`` waits)."""
    node = node_like_the_estimator(f"bench_idle_{kind}", [])
    for t in "xy":
        node.create_publisher(Float64MultiArray, f"/bench_exec/idle_{t}", qos.OUTPUT)
    ex = KEPT[kind]()
    ex.add_node(node)
    for _ in range(50):
        ex.spin_once(timeout_sec=0.0)
    c0 = time.thread_time()
    for _ in range(k):
        ex._wait(0.0)
    cpu = (time.thread_time() - c0) / k * 1e6
    ex.shutdown()
    node.destroy_node()
    return cpu


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--messages", type=int, default=3000)
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--before", type=Path, default=None, help="a checkout whose KeptWaitSetExecutor runs beside")
    ap.add_argument("--idle", type=int, default=0, metavar="K", help="also time K waits with nothing ready per round")
    a = ap.parse_args()
    if a.before is not None:
        KEPT["kept_before"] = executor_from(a.before.resolve())
    rclpy.init()
    res: dict[str, list] = {kind: [] for kind in ("rclpy", *KEPT)}
    idle: dict[str, list] = {kind: [] for kind in KEPT}
    try:
        for r in range(a.rounds):
            for kind in (list(res) if r % 2 == 0 else list(res)[::-1]):
                res[kind].append(one_round(kind, a.messages))
            for kind in (list(idle) if r % 2 == 0 else list(idle)[::-1]):
                if a.idle:
                    idle[kind].append(idle_round(kind, a.idle))
    finally:
        rclpy.try_shutdown()
    print(f"Command: `python bench/bench_executor.py --messages {a.messages} --rounds {a.rounds}"
          f"{f' --before {a.before}' if a.before else ''}{f' --idle {a.idle}' if a.idle else ''}`"
          f" (load {os.getloadavg()[0]:.1f} after)\n")
    print("| executor | CPU per callback (median of rounds) | waits per callback | rounds |")
    print("|---|---|---|---|")
    med = {}
    for kind, rows in res.items():
        med[kind] = statistics.median(r[0] for r in rows)
        print(f"| {kind} | {med[kind]:.0f} us | {statistics.median(r[1] for r in rows):.2f} | "
              f"{', '.join(f'{r[0]:.0f}' for r in rows)} |")
    print(f"\nkept / rclpy: {med['kept'] / med['rclpy']:.2f}x")
    if "kept_before" in med:
        print(f"kept / kept_before: {med['kept'] / med['kept_before']:.2f}x")
    if a.idle:
        print("\nOne wait with nothing ready (CPU, median of rounds): " + ", ".join(
            f"{kind} {statistics.median(v):.1f} us ({', '.join(f'{x:.1f}' for x in v)})" for kind, v in idle.items()))
        if "kept_before" in idle:
            ratio = statistics.median(idle["kept"]) / statistics.median(idle["kept_before"])
            print(f"kept / kept_before: {ratio:.2f}x")
    return 0


if __name__ == "__main__":
    sys.exit(main())
