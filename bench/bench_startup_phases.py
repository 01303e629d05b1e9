#!/usr/bin/env python
"""Where the 32-agent estimator's start-up goes, phase by phase, side by side with other checkouts.

    python bench/bench_startup_phases.py [--rounds 9] [--before DIR] [--table32 FILE]

A camera_sim of ``camera_agents`` with 32 agents publishes (50 Hz, every h = 1 s) with the Fast DDS
profile ``config/fastdds_discovery.xml``; in turn (the order rotated each round, one unmeasured warm-up
round), this checkout's estimator and ``--before``'s are started as the console script starts them, by
``bench/startup_phases_child.py``, which marks the end of each phase: the interpreter, the DDS
participant (:mod:`switchobs_ros.early`), scipy's import, the node's module, the node's construction up
to the system built (``EstimatorConfig.from_values``: the observability decompositions; the table read
ahead in a thread), the table loaded and checked, the observer, ready (publishers, subscriptions), the
first channel and input messages' arrival and the first estimate published. Printed: per phase the
median wall time since the spawn, the median process CPU time, and the median CPU spent in the phase,
and the garbage collector's CPU before the first estimate. A script, not a test: nothing is asserted.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import yaml

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from tools.domain import claim_domain  # noqa: E402
from tools.launch import NodeProcess, ros_args  # noqa: E402

PHASES = ("interpreter", "participant", "scipy imported", "node module imported", "node construction",
          "system built", "table loaded and checked", "observer built", "ready", "first channel arrived",
          "first input arrived", "first estimate published")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--rounds", type=int, default=9)
    ap.add_argument("--before", help="another checkout, started the same way in the same rounds")
    ap.add_argument("--table32", default="/tmp/boot/k32v4.npz", help="the 32-agent Kalman table (.npz)")
    a = ap.parse_args(argv)
    repos = {"this": str(REPO)} | ({"before": a.before} if a.before else {})
    lease = claim_domain()
    env0 = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    env0.update(ROS_DOMAIN_ID=str(lease.domain_id), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST",
                FASTRTPS_DEFAULT_PROFILES_FILE=str(REPO / "config" / "fastdds_discovery.xml"),
                OPENBLAS_NUM_THREADS="1", PYTHONSAFEPATH="1")
    sched = {"schedule.mode": "periodic", "schedule.h": [1.0] * 32}
    res: dict[str, list[dict]] = {k: [] for k in repos}
    with tempfile.TemporaryDirectory(prefix="bench_phases_") as tmp:
        d = Path(tmp)
        sys_path = d / "agents32.yaml"
        sys_path.write_text(yaml.safe_dump({"scenario": "camera_agents", "agents": 32}))
        cam = NodeProcess("camera_sim", ros_args(params=dict(sched, system=str(sys_path), rate=50.0)),
                          log=d / "cam.log", env=dict(env0, PYTHONPATH=str(REPO), PYTHONPYCACHEPREFIX=str(d / "pyc")))
        try:
            time.sleep(2.0)
            args = ros_args(params=dict(sched, system=str(sys_path), gain_table=a.table32))
            for r in range(a.rounds + 1):
                names = list(repos)
                for name in names[r % len(names):] + names[:r % len(names)]:
                    env = dict(env0, PYTHONPATH=repos[name], PYTHONPYCACHEPREFIX=str(d / f"pyc_{name}"),
                               T0=repr(time.monotonic()))
                    p = subprocess.run([sys.executable, str(REPO / "bench" / "startup_phases_child.py"), *args],
                                       env=env, capture_output=True, text=True, timeout=120)
                    line = [x for x in p.stderr.splitlines() if x.startswith("PHASES ")]
                    if not line:
                        print(f"{name}: no first estimate\n{p.stderr[-2000:]}", file=sys.stderr)
                    elif r:
                        res[name].append(json.loads(line[0][len("PHASES "):]))
        finally:
            cam.stop()
            lease.release()
    print(f"{a.rounds} starts each; load average {os.getloadavg()[0]:.1f} at the end\n")
    print("| phase (its end) | " + " | ".join(f"{k}: wall | {k}: CPU | {k}: CPU in the phase" for k in repos) + " |")
    print("|---|" + "---|---|---|" * len(repos))
    for i, ph in enumerate(PHASES):
        cells = []
        for k in repos:
            rows = [m for m in res[k] if ph in m]
            if not rows:
                cells += ["-"] * 3
                continue
            prev = PHASES[max(0, i - 1)]
            cells += [f"{statistics.median(m[ph][0] for m in rows):.3f} s",
                      f"{statistics.median(m[ph][1] for m in rows):.3f} s",
                      f"{statistics.median(m[ph][1] - m.get(prev, m[ph])[1] for m in rows):.3f} s"]
        print(f"| {ph} | " + " | ".join(cells) + " |")
    for k in repos:
        last = [m["first estimate published"] for m in res[k]]
        if last:
            gc_s, gc_n = statistics.median(x[2] for x in last), statistics.median(x[3] for x in last)
            print(f"- {k}: garbage collection before the first estimate {gc_s:.3f} s CPU "
                  f"({gc_n:.0f} collections); first estimate per start (s): "
                  + ", ".join(f"{x[0]:.2f}" for x in last))
    return 0


if __name__ == "__main__":
    sys.exit(main())
