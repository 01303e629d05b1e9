#!/usr/bin/env python
"""The estimator node over DDS at 32 agents with a sender stamping on its own clock.

    python bench/bench_own_clock.py                 # 32 agents, 50 Hz, 40 s per run (a few minutes)
    python bench/bench_own_clock.py --agents 8 --seconds 20

camera_sim and the estimator as separate processes (``tools/demo.py``, the system clock, no
``/clock``), the built-in ``camera_agents`` model with M agents (every h_i = 1 s, 50 Hz, noise-free
plant from a random state, the estimate from zero) and its Kalman table (``.npz``). Side by side in
one run: camera_sim stamping every tick on the nominal grid (``epoch + k / rate``), and stamping it
with its node clock at send (``stamp_at_send``: the timer's jitter in every stamp; the Kalman table
leaves its cache at the first off-grid stamp and the square-root recursion runs from there).
Reported per run: ticks published (truth messages), samples answered, the fraction, withdrawn
bounds, published estimates above the published exact bound, the error at the end against the
state's norm, and the CPU of the estimator process.

A script, not a test: nothing is asserted (test/ros/test_own_clock_stamps.py is the test).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import yaml

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "bench"))

from bench_design import machine_info  # noqa: E402

from switchobs_core.threads import single_threaded_blas  # noqa: E402

single_threaded_blas()

import switchobs_core as so  # noqa: E402
from tools import demo  # noqa: E402


def run(m: int, seconds: float, rate: float, d: Path) -> list[dict]:
    spec = {"scenario": "camera_agents", "agents": m}
    sys_path = d / f"agents{m}.yaml"
    sys_path.write_text(yaml.safe_dump(spec))
    system = so.load_system(sys_path)
    cycle = so.Cycle([1.0] * m)
    t = time.process_time()
    table = so.kalman_table(system, [so.design_kalman(system, cycle, rate)]).save(d / f"kalman{m}.npz")
    design_cpu = time.process_time() - t
    x0 = np.random.default_rng(1).uniform(-1.0, 1.0, system.n)
    sched = {"schedule.mode": "periodic", "schedule.h": [1.0] * m}
    rows = []
    for label, stamp_at_send in (("grid", False), ("own clock at send", True)):
        res = demo.run("periodic", duration=seconds, time_scale=1.0, rate=rate, init="zeros", gain_table=str(table),
                       out=None, quiet=True, schedule_params=sched, system=str(sys_path), initial_state=tuple(x0),
                       extra_camera={"publish_clock": False, "stamp_at_send": stamp_at_send})
        exact = res["exact"]
        valid = exact > 0
        false = int(np.count_nonzero(valid & (res["err"] > exact * (1 + 1e-6) + 1e-12)))
        stamps = np.array(res["stamps"], dtype=np.int64)
        off = int(np.count_nonzero(np.mod(stamps - stamps[0], round(1e9 / rate))))
        rows.append({"M": m, "n": system.n, "stamps": label, "published": res["n_truth"], "answered": res["n_state"],
                     "off_grid": off, "withdrawn": int(np.count_nonzero(~valid)), "false": false,
                     "final_rel": float(res["err"][-1] / max(np.linalg.norm(x0), 1e-300)),
                     "design_cpu": design_cpu, "wall": res["wall"]})
    return rows


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--agents", type=int, default=32)
    ap.add_argument("--seconds", type=float, default=40.0)
    ap.add_argument("--rate", type=float, default=50.0)
    a = ap.parse_args(argv)
    info = machine_info()
    with tempfile.TemporaryDirectory(prefix="bench_own_clock_") as tmp:
        rows = run(a.agents, a.seconds, a.rate, Path(tmp))
    print(f"Machine: {info['cpu']}, {info['nproc']} cores, Python {info['python']}; commit {info['commit']}; "
          f"load average {info['load'][0]:.1f} before ({info['date']}).")
    print(f"Command: `OPENBLAS_NUM_THREADS=1 python bench/bench_own_clock.py --agents {a.agents} "
          f"--seconds {a.seconds:g} --rate {a.rate:g}`\n")
    print("| M (n) | stamps | ticks published | answered | fraction | off the grid | bounds withdrawn "
          "| above the exact bound | final error / ||x(0)|| |")
    print("|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['M']} ({r['n']}) | {r['stamps']} | {r['published']} | {r['answered']} "
              f"| {r['answered'] / max(r['published'], 1):.4f} | {r['off_grid']} | {r['withdrawn']} | {r['false']} "
              f"| {r['final_rel']:.2e} |")
    print(f"\nKalman design CPU {rows[0]['design_cpu']:.1f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
