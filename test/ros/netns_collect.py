"""The observer of a network-namespace test (test_netns.py), run on a host of its own: for each
robot namespace it keeps ``sim/truth``, ``estimator/state``, ``estimator/envelope`` and the
estimator's ``/diagnostics``, until the truth has stopped for ``--quiet`` seconds (camera_sim
finished) or ``--timeout`` passes, and writes a JSON summary per robot: every published estimate
checked against the truth at its stamp and the guaranteed bound published with it (the envelope's
last element: ``noise_bound`` with a declared ``noise.max``, else ``exact_bound``; -1 = withdrawn).

    python test/ros/netns_collect.py OUT.json --robots /robot1 /robot2 [--quiet 2] [--timeout 40]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

import numpy as np
import rclpy
from diagnostic_msgs.msg import DiagnosticArray

from switchobs_ros import qos
from tools.launch import Collector

#: The diagnostics keys a summary keeps (the estimator's /diagnostics).
KEYS = ("lost channel messages", "late channel messages", "inconsistent samples (rejected, bounds withdrawn)",
        "partial updates", "updates", "exact bound valid", "e0", "re-certifications from data",
        "samples not proven within the reorder window (channel rows dropped)",
        "samples not proven within the reorder window, named by the consistency test")


def summary(data: dict, labels: dict, diag: dict, ns: str) -> dict:
    truth, state, env = (data[f"{ns}/{t}"] for t in ("sim/truth", "estimator/state", "estimator/envelope"))
    common = sorted(set(truth) & set(state) & set(env))
    out = {"truth": len(truth), "estimates": len(state), "checked": len(common), "diagnostics": diag.get(ns, {})}
    if not common:
        return out
    t0 = min(truth)
    err = np.array([np.linalg.norm(state[s] - truth[s]) for s in common])
    bound = np.array([env[s][-1] for s in common])
    t = np.array([(s - t0) * 1e-9 for s in common])
    valid = bound >= 0
    above = valid & (err > bound)
    late = t >= 5.0
    out.update(bound_label=labels.get(f"{ns}/estimator/envelope", ("?",))[-1], valid=int(valid.sum()),
               above=int(above.sum()), max_ratio=float(np.max(err[valid] / bound[valid])) if valid.any() else None,
               final_error=float(err[-1]), final_bound=float(bound[-1]),
               answered_after_5s=float(late.sum() / max(1, sum(1 for s in truth if (s - t0) * 1e-9 >= 5.0))),
               valid_after_5s=float((valid & late).sum() / max(1, late.sum())))
    return out


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("out")
    ap.add_argument("--robots", nargs="+", default=[""])
    ap.add_argument("--quiet", type=float, default=2.0)
    ap.add_argument("--timeout", type=float, default=40.0)
    a = ap.parse_args()
    robots = ["" if r in ("", "/") else "/" + r.strip("/") for r in a.robots]
    rclpy.init()
    topics = [f"{ns}/{t}" for ns in robots for t in ("sim/truth", "estimator/state", "estimator/envelope")]
    node = Collector(topics, name="netns_collector")
    diag: dict[str, dict] = {}

    def on_diag(msg: DiagnosticArray) -> None:
        for st in msg.status:                           # "<fully qualified node name>: observer"
            ns = st.name.split(":")[0].rsplit("/", 1)[0]
            if ns in robots:
                diag.setdefault(ns, {}).update({kv.key: kv.value for kv in st.values if kv.key in KEYS})

    node.create_subscription(DiagnosticArray, "/diagnostics", on_diag, qos.OUTPUT)
    start = time.monotonic()
    seen = 0.0
    while time.monotonic() - start < a.timeout:
        rclpy.spin_once(node, timeout_sec=0.05)
        last = max((v for ns in robots for v in node.arrival[f"{ns}/sim/truth"].values()), default=0.0)
        if last:
            seen = last
        if seen and time.time() - seen > a.quiet:
            break
    for _ in range(20):                                  # the last answers and diagnostics
        rclpy.spin_once(node, timeout_sec=0.05)
    res = {ns or "/": summary(node.data, node.labels, diag, ns) for ns in robots}
    Path(a.out).write_text(json.dumps(res, indent=1))
    node.destroy_node()
    rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
