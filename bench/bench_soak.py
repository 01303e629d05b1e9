"""Soak benchmark of the estimator node over DDS (not a test): a long run at a fixed rate with
corrupted messages mixed in.

``python bench/bench_soak.py [--minutes 10] [--rate 500] [--corrupt 0.01] [--seed 0]``

A driver process publishes, at ``rate`` Hz, a camera/pose + target/pose pair stamped with the
send time, and the active channel of the paper's periodic (2 s, 0.6) schedule whenever it
changes. With probability ``corrupt`` per published message it also mixes in a corrupted one:
NaN or inf in a pose field, 1e300, a wrong frame, a zero, negative, older, duplicate or future
stamp, or a channel value 0 / 3..255. The estimator runs in its own process. Measured:

* crashes: the estimator process is alive at the end and exits 0 on SIGINT;
* non-finite outputs: every ``~/state`` and ``~/envelope`` message is checked;
* answers: every valid pair's stamp must come back on ``~/state``; a stamp that does not is
  attributed to the transport only if the node's own counters (accepted + rejected) show that
  many pose messages never arrived (the sensor topics are best effort);
* memory: the estimator's RSS (``/proc/PID/status``) every 10 s; reported at start (after
  the first 10 s), at the end, and the largest value.

Writes a Markdown section to stdout (and to ``--out``), recorded in bench/RESULTS.md.
"""

from __future__ import annotations

import argparse
import math
import os
import platform
import sys
import tempfile
import threading
import time
from collections import Counter
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _pacing import sleep_until

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

S = 1_000_000_000
CORRUPTIONS = ("nan", "inf", "huge", "frame", "zero", "negative", "older", "duplicate", "future", "channel")


def rss_kib(pid: int) -> int:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1])
    return -1


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--minutes", type=float, default=10.0)
    ap.add_argument("--rate", type=float, default=500.0, help="pairs per second")
    ap.add_argument("--corrupt", type=float, default=0.01, help="probability of a corrupted extra message")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", default="")
    a = ap.parse_args(argv)

    from tools.domain import claim_domain, localhost_env

    lease = claim_domain()
    os.environ.update(localhost_env(lease.domain_id))
    import rclpy
    from diagnostic_msgs.msg import DiagnosticArray
    from geometry_msgs.msg import PoseStamped
    from rclpy.executors import SingleThreadedExecutor
    from std_msgs.msg import Float64MultiArray, UInt8

    import msg_bridge as mb
    from switchobs_core.design.lmi import design_table
    from switchobs_core.model.scenarios import load_system
    from switchobs_core.model.schedule import Cycle, PeriodicSchedule
    from switchobs_ros import qos
    from tools.launch import NodeProcess, ros_args

    tmp = Path(tempfile.mkdtemp(prefix="bench_soak_"))
    cycle = Cycle.from_ts(2.0, 0.6)
    table = str(design_table(load_system("paper"), [cycle], progress=False).save(tmp / "paper.json"))
    sched = PeriodicSchedule(cycle)
    rclpy.init()
    node = rclpy.create_node("soak_driver")
    pub_cam = node.create_publisher(PoseStamped, "camera/pose", qos.SENSOR)
    pub_tgt = node.create_publisher(PoseStamped, "target/pose", qos.SENSOR)
    pub_ch = node.create_publisher(UInt8, "camera/active_channel", qos.CHANNEL_PUB)
    answered: set[int] = set()
    nonfinite = Counter()
    outputs = Counter()
    last_diag: dict[str, str] = {}

    def on_state(msg):
        arr = mb.unpack_labelled(msg)
        outputs["state"] += 1
        if not np.isfinite(arr.values).all():
            nonfinite["state"] += 1
        answered.add(arr.stamp_ns)

    def on_env(msg):
        arr = mb.unpack_labelled(msg)
        outputs["envelope"] += 1
        if not np.isfinite(arr.values).all():
            nonfinite["envelope"] += 1

    def on_diag(msg):
        for st in msg.status:
            if "estimator" in st.name:
                last_diag.update({kv.key: kv.value for kv in st.values})

    node.create_subscription(Float64MultiArray, "/estimator/state", on_state, qos.TRUTH)
    node.create_subscription(Float64MultiArray, "/estimator/envelope", on_env, qos.TRUTH)
    node.create_subscription(DiagnosticArray, "/diagnostics", on_diag, qos.OUTPUT)
    est = NodeProcess("estimator", ros_args(params={"gain_table": table, "diagnostics_period": 1.0}),
                      log=tmp / "estimator.log")
    ex = SingleThreadedExecutor()
    ex.add_node(node)
    stop = threading.Event()
    spinner = threading.Thread(target=lambda: [ex.spin_once(timeout_sec=0.01) for _ in iter(stop.is_set, True)])
    spinner.start()
    rss: list[tuple[float, int]] = []
    sent_valid: list[int] = []
    sent = Counter()
    rng = np.random.default_rng(a.seed)
    try:
        end = time.monotonic() + 60
        while not (pub_tgt.get_subscription_count() and pub_cam.get_subscription_count()
                   and node.count_publishers("/estimator/state")):
            time.sleep(0.05)
            if time.monotonic() > end:
                raise RuntimeError("estimator not discovered: " + est.output())
        time.sleep(1.0)
        t_start = time.monotonic()
        rss.append((0.0, rss_kib(est.pid)))
        n = int(a.rate * a.minutes * 60)
        period = 1.0 / a.rate
        t_next = time.perf_counter()
        next_rss = 10.0
        channel = 0
        last = {"camera": None, "target": None}
        t0_ns = time.time_ns()

        def corrupted(part: str, s: int):
            kind = str(rng.choice(CORRUPTIONS))
            if kind == "channel":
                pub_ch.publish(UInt8(data=int(rng.choice([0, *range(3, 256)]))))
                sent["bad_channel"] += 1
                return
            m = mb.xy_to_pose((1.0, 2.0), s + 1, "map")
            if kind in ("nan", "inf", "huge"):
                field = str(rng.choice(["x", "y", "z"]))
                setattr(m.pose.position, field, {"nan": math.nan, "inf": math.inf, "huge": 1e300}[kind])
            elif kind == "frame":
                m.header.frame_id = "odom"
            elif kind == "zero":
                m.header.stamp = mb.ns_to_stamp(0)
            elif kind == "negative":
                m.header.stamp.sec = -7
            elif kind == "older":
                m.header.stamp = mb.ns_to_stamp(s - 5 * S)
            elif kind == "duplicate":
                m.header.stamp = mb.ns_to_stamp(last[part])
            elif kind == "future":
                m.header.stamp = mb.ns_to_stamp(time.time_ns() + 30 * S)
            (pub_cam if part == "camera" else pub_tgt).publish(m)
            sent[f"bad_{kind}"] += 1

        for k in range(n):
            sleep_until(t_next)
            t_next += period
            s = time.time_ns()
            c = sched.channel_at((s - t0_ns) * 1e-9)
            if c != channel:
                pub_ch.publish(UInt8(data=c))
                channel = c
            pub_cam.publish(mb.xy_to_pose((0.001 * (k % 1000), 0.0), s, "map"))
            last["camera"] = s
            if rng.random() < a.corrupt:
                corrupted("camera", s)
            pub_tgt.publish(mb.xy_to_pose((3.0, 1.0), s, "map"))
            last["target"] = s
            if rng.random() < a.corrupt:
                corrupted("target", s)
            sent_valid.append(s)
            el = time.monotonic() - t_start
            if el >= next_rss:
                rss.append((el, rss_kib(est.pid)))
                next_rss += 10.0
        elapsed = time.monotonic() - t_start
        deadline = time.monotonic() + 5.0
        while time.monotonic() < deadline and len(answered) < len(sent_valid):
            time.sleep(0.05)
        time.sleep(2.5)                          # a diagnostics period with the final counters
        rss.append((time.monotonic() - t_start, rss_kib(est.pid)))
        alive = est.alive()
    finally:
        rc = est.stop()
        stop.set()
        spinner.join()
        node.destroy_node()
        rclpy.try_shutdown()
    missing = [s for s in sent_valid if s not in answered]
    sent_poses = 2 * len(sent_valid) + sum(v for k, v in sent.items() if k != "bad_channel")
    received = sum(int(v) for k, v in last_diag.items()
                   if k in ("camera/pose accepted", "target/pose accepted")
                   or (k.startswith("rejected ") and "pose" in k))
    rej = {k[len("rejected "):]: v for k, v in last_diag.items() if k.startswith("rejected ") and k != "rejected total"}
    r_start = rss[1][1] if len(rss) > 2 else rss[0][1]
    r_end = rss[-1][1]
    bad = ", ".join(f"{k[4:]} {v}" for k, v in sorted(sent.items()))
    lost = max(sent_poses - received, 0)
    samples = ", ".join(f"{t:.0f}: {r / 1024:.1f}" for t, r in rss[:: max(len(rss) // 12, 1)])
    lines = [
        "### Soak: the estimator node at a fixed rate with corrupted messages (bench/bench_soak.py)",
        "",
        f"{time.strftime('%Y-%m-%d')}, {platform.node()}, {os.cpu_count()} cores, Python {platform.python_version()}, "
        f"ROS 2 Jazzy wheels, localhost only; load average at the end {os.getloadavg()[0]:.1f}.",
        f"Run: {a.minutes:g} min requested, {elapsed / 60:.2f} min sent, {a.rate:g} pairs/s "
        f"(achieved {len(sent_valid) / elapsed:.1f}), corrupted extra messages with probability {a.corrupt:g} "
        f"per message, seed {a.seed}.",
        "",
        "| quantity | value |",
        "|---|---|",
        f"| estimator alive at the end / exit code on SIGINT | {alive} / {rc} |",
        f"| valid pairs sent | {len(sent_valid)} |",
        f"| corrupted messages sent | {sum(sent.values())} ({bad}) |",
        f"| valid pairs answered on `~/state` | {len(sent_valid) - len(missing)} |",
        f"| pose messages sent / received by the node (accepted + rejected) | {sent_poses} / {received} |",
        f"| unanswered valid pairs / pose messages lost in transport | {len(missing)} / {lost} |",
        f"| non-finite outputs (`~/state`, `~/envelope`) | {nonfinite['state']}, {nonfinite['envelope']} "
        f"(of {outputs['state']}, {outputs['envelope']}) |",
        f"| internal errors / resets / estimates withheld | {last_diag.get('internal errors', '?')} / "
        f"{last_diag.get('resets', '?')} / {last_diag.get('estimates withheld (non-finite, then reset)', '?')} |",
        f"| rejected by the node (diagnostics) | {', '.join(f'{k} {v}' for k, v in sorted(rej.items()))} |",
        f"| estimator RSS at start (10 s) / end / max (MiB) | {r_start / 1024:.1f} / {r_end / 1024:.1f} / "
        f"{max(r for _, r in rss) / 1024:.1f} |",
        f"| RSS samples (s: MiB) | {samples} |",
    ]
    text = "\n".join(lines) + "\n"
    print(text)
    if a.out:
        Path(a.out).write_text(text)
    return 0 if alive and rc == 0 and not nonfinite and not missing else 1


if __name__ == "__main__":
    sys.exit(main())
