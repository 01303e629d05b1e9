"""Taking an input pose and checking it, in process: serialised bytes read by msg_bridge.parse
against the Python message rclpy builds.

One node publishes ``--batch`` PoseStamped messages on a topic that two subscriptions of the same
process take (keep-last, depth >= batch): one with ``raw=True`` (the estimator's input path:
``take_message`` gives the bytes, :meth:`Source.checked <switchobs_ros.sources.Source.checked>`
parses and checks them), one without (``take_message`` builds a ``PoseStamped``, ``checked``
reads it). Each round times the take + check of the whole batch on each, alternating which goes
first; the table gives the medians over rounds, per message, and their ratio.

``--checkout DIR`` also runs the message path of another checkout (e.g. the main branch) in child
processes, ``--blocks`` times in turn with this one's (a block of rounds here, then one there), so
that both are measured on the same machine in the same minutes.

    OPENBLAS_NUM_THREADS=1 python bench/bench_take.py --rounds 5 --blocks 3 --batch 500 --checkout /tmp/take-base
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time


def _measure(rounds: int, batch: int, raw_too: bool) -> dict[str, list[float]]:
    import rclpy
    from geometry_msgs.msg import PoseStamped
    from rclpy.qos import QoSProfile

    import msg_bridge as mb
    from switchobs_core.model.scenarios import load_system
    from switchobs_ros.sources import sources_from_specs

    system = load_system("paper")
    src = sources_from_specs(mb.default_inputs(system), system)[1]       # target/pose
    rclpy.init()
    node = rclpy.create_node("bench_take")
    qos = QoSProfile(depth=batch + 10)
    topic = f"bench_take_{os.getpid()}/pose"
    pub = node.create_publisher(PoseStamped, topic, qos)
    subs = {"message": node.create_subscription(PoseStamped, topic, lambda m: None, qos)}
    if raw_too:
        subs["raw"] = node.create_subscription(PoseStamped, topic, lambda m: None, qos, raw=True)
    out: dict[str, list[float]] = {k: [] for k in subs}
    base = time.time_ns() - 10**12
    try:
        deadline = time.monotonic() + 10
        while time.monotonic() < deadline and pub.get_subscription_count() < len(subs):
            time.sleep(0.05)
        time.sleep(0.3)
        for r in range(rounds + 1):                  # round 0 warms up
            for k in range(batch):
                pub.publish(mb.xy_to_pose((0.1 * k, 0.2), base + (r * batch + k + 1) * 1_000_000, "map"))
            time.sleep(0.2)                          # delivered (same host)
            order = list(subs) if r % 2 == 0 else list(subs)[::-1]
            for name in order:
                sub = subs[name]
                last = None
                n = 0
                t0 = time.perf_counter()
                while True:
                    with sub.handle:
                        got = sub.handle.take_message(sub.msg_type, sub.raw)
                    if got is None:
                        break
                    stamp, _, rej = src.checked(got[0], frame_id="map", max_abs=1e6, last_ns=last,
                                                now_ns=0, future_tolerance_ns=500_000_000)
                    if rej is None:
                        last = stamp
                    n += 1
                dt = time.perf_counter() - t0
                if n != batch:
                    raise SystemExit(f"{name}: took {n} of {batch} messages (raise the sleep or lower --batch)")
                if r:
                    out[name].append(dt / n * 1e6)
    finally:
        node.destroy_node()
        rclpy.shutdown()
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--rounds", type=int, default=15)
    ap.add_argument("--blocks", type=int, default=3)
    ap.add_argument("--batch", type=int, default=500)
    ap.add_argument("--checkout", default=None, help="also time the message path of this checkout")
    ap.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    a = ap.parse_args()
    from switchobs_ros.sources import Source
    raw_too = "parser" in Source.__dataclass_fields__
    if a.child:
        print(json.dumps(_measure(a.rounds, a.batch, raw_too)))
        return
    res: dict[str, list[float]] = {}
    for _ in range(a.blocks):
        for k, v in _measure(a.rounds, a.batch, raw_too).items():
            res.setdefault(k, []).extend(v)
        if a.checkout:
            env = dict(os.environ, PYTHONPATH=a.checkout)
            got = subprocess.run([sys.executable, os.path.abspath(__file__), "--rounds", str(a.rounds), "--batch",
                                  str(a.batch), "--child"], env=env, cwd=a.checkout, stdout=subprocess.PIPE,
                                 text=True, check=True)
            res.setdefault("message, checkout", []).extend(json.loads(got.stdout)["message"])
    med = {k: statistics.median(v) for k, v in res.items()}
    ref = med.get("message, checkout", med["message"])
    print(f"take + check of a PoseStamped, us per message (median of {a.blocks} x {a.rounds} rounds of {a.batch}; "
          f"ratio to {'the checkout' if a.checkout else 'the message path'})")
    for k, v in med.items():
        print(f"  {k:20s} {v:7.2f} us   {v / ref:5.2f}x")


if __name__ == "__main__":
    main()
