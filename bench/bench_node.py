"""Benchmark of the estimator node over DDS (not a test): throughput, latency, start-up.

``python bench/bench_node.py [--seconds 3] [--rates 250,500,1000,2000,3000]``

1. Latency and the highest rate answered in full. A driver process publishes measurements
   (camera/pose + target/pose, same stamp = the send time) at a fixed rate and listens to the
   answers. Side by side in one run:
   * the estimator (separate process; answers on ``~/state``, reliable);
   * the ceiling: a bare rclpy node (separate process) that republishes each target PoseStamped,
     with the same QoS as the estimator (sensor-data subscriptions, depth 50; reliable output).
   Latency = arrival time of the answer - the measurement's header stamp (same clock: both
   are this machine's system time). A rate "passes" when every measurement is answered and
   p99 latency < 2 ms.
2. Start-up: spawn -> the node's ``~/state`` publisher is discovered, and spawn -> first
   answer, with a cached gain table and with design at start-up (empty cache folder).

Writes a Markdown section to stdout (recorded in bench/RESULTS.md).
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _pacing import sleep_until

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

RATES = (250, 500, 1000, 2000, 3000)


def republisher_main() -> None:
    """The ceiling: republish every target/pose as it arrives."""
    import rclpy
    from geometry_msgs.msg import PoseStamped
    from rclpy.executors import ExternalShutdownException

    from switchobs_ros import qos

    rclpy.init(args=sys.argv)
    node = rclpy.create_node("bare_republisher")
    pub = node.create_publisher(PoseStamped, "~/out", qos.OUTPUT)
    node.create_subscription(PoseStamped, "target/pose", pub.publish, qos.SENSOR_SUB)
    node.create_subscription(PoseStamped, "camera/pose", lambda m: None, qos.SENSOR_SUB)
    try:
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()


class Driver:
    def __init__(self, node, ns: str, answer_type, answer_topic: str):
        from geometry_msgs.msg import PoseStamped
        from std_msgs.msg import UInt8

        from switchobs_ros import qos

        self.node = node
        self.pub_cam = node.create_publisher(PoseStamped, f"/{ns}/camera/pose", qos.SENSOR)
        self.pub_tgt = node.create_publisher(PoseStamped, f"/{ns}/target/pose", qos.SENSOR)
        self.pub_ch = node.create_publisher(UInt8, f"/{ns}/camera/active_channel", qos.CHANNEL_PUB)
        self.arrivals: dict[int, int] = {}
        self.sub = node.create_subscription(answer_type, answer_topic, self._answer, qos.TRUTH)
        self._stamp_of = _stamp_of_array if answer_type.__name__ == "Float64MultiArray" else _stamp_of_pose

    def _answer(self, msg) -> None:
        self.arrivals[self._stamp_of(msg)] = time.time_ns()

    def matched(self) -> bool:
        return (self.pub_tgt.get_subscription_count() > 0 and self.pub_cam.get_subscription_count() > 0
                and self.node.count_publishers(self.sub.topic_name) > 0)


def _stamp_of_array(msg) -> int:
    return int(msg.data[0]) * 1_000_000_000 + int(msg.data[1])


def _stamp_of_pose(msg) -> int:
    return msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec


def run_rate(driver: Driver, rate: float, seconds: float) -> dict:
    import rclpy
    from std_msgs.msg import UInt8

    import msg_bridge as mb

    driver.pub_ch.publish(UInt8(data=1))
    driver.arrivals.clear()
    sent: list[int] = []
    n = int(rate * seconds)
    period = 1.0 / rate

    def send():
        t_next = time.perf_counter()
        for k in range(n):
            sleep_until(t_next)
            s = time.time_ns()
            driver.pub_cam.publish(mb.xy_to_pose((0.001 * k, 0.0), s, "map"))
            driver.pub_tgt.publish(mb.xy_to_pose((3.0, 1.0), s, "map"))
            sent.append(s)
            t_next += period

    th = threading.Thread(target=send)
    th.start()
    while th.is_alive():
        rclpy.spin_once(driver.node, timeout_sec=0.001)
    end = time.monotonic() + 1.0
    while time.monotonic() < end and len(driver.arrivals) < len(sent):
        rclpy.spin_once(driver.node, timeout_sec=0.01)
    lat = np.array([(driver.arrivals[s] - s) * 1e-6 for s in sent if s in driver.arrivals])
    achieved = (len(sent) - 1) / ((sent[-1] - sent[0]) * 1e-9) if len(sent) > 1 else 0.0
    return {"rate": rate, "achieved": achieved, "sent": len(sent), "answered": len(lat),
            "p50": float(np.median(lat)) if lat.size else np.nan,
            "p99": float(np.percentile(lat, 99)) if lat.size else np.nan,
            "max": float(lat.max()) if lat.size else np.nan}


def startup(cache_dir: str | None, table: str, domain_env: dict) -> dict:
    """Seconds from spawn to the ~/state publisher being seen, and to the first answer."""
    import rclpy
    from std_msgs.msg import Float64MultiArray

    from tools.launch import NodeProcess, ros_args

    params = {"gain_table": table}
    if cache_dir is not None:
        params = {"gain_table": "", "gain_table_cache_dir": cache_dir}
    node = rclpy.create_node("bench_startup")
    drv = Driver(node, "su", Float64MultiArray, "/su/estimator/state")
    t0 = time.monotonic()
    t0_ns = time.time_ns()
    proc = NodeProcess("estimator", ros_args(params=params) + ["-r", "__ns:=/su"], env=domain_env)
    try:
        while not drv.matched():
            rclpy.spin_once(node, timeout_sec=0.005)
            if time.monotonic() - t0 > 120:
                raise RuntimeError("estimator did not start")
        t_up = time.monotonic() - t0
        r = run_rate(drv, 100, 0.5)
        assert r["answered"] > 0, proc.output()
        t_answer = (min(drv.arrivals.values()) - t0_ns) * 1e-9
    finally:
        proc.stop()
        node.destroy_node()
    return {"discovered": t_up, "first_answer": t_answer}


def main(argv=None) -> int:
    if "--republisher" in sys.argv:
        republisher_main()
        return 0
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seconds", type=float, default=3.0)
    ap.add_argument("--rates", default=",".join(map(str, RATES)))
    a = ap.parse_args(argv)
    from tools.domain import claim_domain, localhost_env

    lease = claim_domain()
    os.environ.update(localhost_env(lease.domain_id))
    import rclpy
    from geometry_msgs.msg import PoseStamped
    from std_msgs.msg import Float64MultiArray

    from switchobs_core.design import design_table
    from switchobs_core.scenarios import load_system
    from switchobs_core.schedule import Cycle
    from tools.launch import NodeProcess, ros_args

    tmp = Path(tempfile.mkdtemp(prefix="bench_node_"))
    table = str(design_table(load_system("paper"), [Cycle.from_ts(2.0, 0.6)]).save(tmp / "paper.json"))
    rclpy.init()
    node = rclpy.create_node("bench_driver")
    # future_tolerance: the driver's stamps are the send time, never ahead; defaults otherwise
    est = NodeProcess("estimator", ros_args(params={"gain_table": table}) + ["-r", "__ns:=/est"],
                      log=tmp / "estimator.log")
    rep = NodeProcess("republisher", ["-r", "__ns:=/bare"],
                      cmd=[sys.executable, __file__, "--republisher", "--ros-args"], log=tmp / "rep.log")
    drivers = {"estimator": Driver(node, "est", Float64MultiArray, "/est/estimator/state"),
               "bare republisher": Driver(node, "bare", PoseStamped, "/bare/bare_republisher/out")}
    results: dict[str, list[dict]] = {k: [] for k in drivers}
    try:
        end = time.monotonic() + 60
        while not all(d.matched() for d in drivers.values()):
            rclpy.spin_once(node, timeout_sec=0.05)
            if time.monotonic() > end:
                raise RuntimeError("nodes not discovered: " + est.output() + rep.output())
        for d in drivers.values():       # warm-up (caches, first expm)
            run_rate(d, 200, 0.5)
        for rate in [float(r) for r in a.rates.split(",")]:
            for name, d in drivers.items():
                results[name].append(run_rate(d, rate, a.seconds))
                time.sleep(0.3)
    finally:
        est.stop()
        rep.stop()
    env = localhost_env(lease.domain_id)
    st_cached = startup(None, table, env)
    st_design = startup(str(tmp / "empty_cache"), table, env)
    node.destroy_node()
    rclpy.try_shutdown()

    def passes(r):
        return r["answered"] == r["sent"] and r["p99"] < 2.0

    print(f"### Estimator node over DDS (bench/bench_node.py)\n\n"
          f"{time.strftime('%Y-%m-%d')}, {platform.node()}, {os.cpu_count()} cores, Python "
          f"{platform.python_version()}, ROS 2 Jazzy wheels (rmw_fastrtps_cpp), localhost only; "
          f"{a.seconds:g} s per rate; each measurement is a camera/pose + target/pose pair.\n")
    print("| rate (Hz) | node | achieved send rate | answered | p50 latency (ms) | p99 (ms) | max (ms) | pass |")
    print("|---:|---|---:|---:|---:|---:|---:|:---:|")
    for i in range(len(results["estimator"])):
        for name in drivers:
            r = results[name][i]
            print(f"| {r['rate']:g} | {name} | {r['achieved']:.0f} | {r['answered']}/{r['sent']} | {r['p50']:.3f} "
                  f"| {r['p99']:.3f} | {r['max']:.2f} | {'yes' if passes(r) else 'no'} |")
    best = {k: max([r["rate"] for r in v if passes(r)], default=0.0) for k, v in results.items()}
    ratio = best["estimator"] / max(best["bare republisher"], 1)
    print(f"\nHighest rate answered in full with p99 < 2 ms: estimator **{best['estimator']:g} Hz**, bare "
          f"republisher {best['bare republisher']:g} Hz (ratio {ratio:.2f}).")
    for i, r in enumerate(results["estimator"]):
        b = results["bare republisher"][i]
        print(f"- {r['rate']:g} Hz: median latency estimator / bare = {r['p50']:.3f} / {b['p50']:.3f} ms "
              f"(ratio {r['p50'] / b['p50']:.2f})")
    print(f"\nStart-up (spawn -> ~/state discovered / -> first answer): cached table "
          f"{st_cached['discovered']:.2f} s / {st_cached['first_answer']:.2f} s; design at start-up "
          f"{st_design['discovered']:.2f} s / {st_design['first_answer']:.2f} s.")
    lease.release()
    return 0


if __name__ == "__main__":
    sys.exit(main())
