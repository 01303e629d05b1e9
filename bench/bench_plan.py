#!/usr/bin/env python
"""Benchmark of ``switchobs plan``: the schedule optimiser on the paper's model.

    python bench/bench_plan.py            # 3 runs each, prints a markdown section

What is measured (median of 3 runs, [min - max]; the machine is shared and noisy):

1. ``plan_schedule(paper_system(), 100.0)`` in process with the CLI defaults (h_min 0.5 s, tau_max 4 s,
   default noise, W = I), a fresh cost cache per run: the optimisation itself. Goal < 10 s.
2. ``switchobs plan paper --rate 100 --json`` as a subprocess, end to end: interpreter start,
   imports, the optimisation, the paper's LMI design of the planned cycle (cvxpy), the Kalman
   design and the costs of the paper's four cycles.

Also printed: the planned schedule, its cost and the cost of the paper's four cycles (the
same cost, the periodic Kalman filter's mean a-priori covariance trace at 100 Hz).
A script, not a test: nothing is asserted.
"""

from __future__ import annotations

import json
import os
import platform
import statistics
import subprocess
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
if str(REPO) not in sys.path:
    sys.path.insert(0, str(REPO))

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

RATE = 100.0
RUNS = 3
DEAD = 0.2


def _stat(ts: list[float]) -> str:
    return f"{statistics.median(ts):.2f} s [{min(ts):.2f} - {max(ts):.2f}] (n={len(ts)})"


def main() -> int:
    from switchobs_core.design.plan import ScheduleCost, cycle_cost, plan_schedule
    from switchobs_core.model.scenarios import paper_system
    from switchobs_core.model.schedule import Cycle
    from switchobs_core.paper import TABLE
    from switchobs_core.threads import single_threaded_blas

    single_threaded_blas()
    system = paper_system()
    load0 = os.getloadavg()
    t_plan, res = [], None
    for _ in range(RUNS):
        t = time.perf_counter()
        res = plan_schedule(system, RATE, progress=False)
        t_plan.append(time.perf_counter() - t)
    t_dead, res_d = [], None          # with a 0.2 s dead time after each switch, h_min 0.1 s
    for _ in range(RUNS):
        t = time.perf_counter()
        res_d = plan_schedule(system, RATE, h_min=0.1, progress=False,
                              cost=ScheduleCost(system, RATE, dead_time=DEAD))
        t_dead.append(time.perf_counter() - t)
    t_cli, out = [], None
    env = dict(os.environ, PYTHONPATH=str(REPO))
    for _ in range(RUNS):
        t = time.perf_counter()
        p = subprocess.run([sys.executable, "-m", "switchobs_core.cli", "plan", "paper", "--rate", f"{RATE:g}",
                            "--json"], capture_output=True, text=True, env=env, check=True)
        t_cli.append(time.perf_counter() - t)
        out = json.loads(p.stdout)
    J = ScheduleCost(system, RATE)
    paper = [(tau, s, cycle_cost(J, Cycle.from_ts(tau, s))) for (tau, s), _, _ in TABLE]
    commit = subprocess.run(["git", "-C", str(REPO), "rev-parse", "--short", "HEAD"],
                            capture_output=True, text=True).stdout.strip()
    print("## Schedule planning: `bench/bench_plan.py`")
    print()
    print(f"{time.strftime('%Y-%m-%d %H:%M')} UTC, nproc {os.cpu_count()}, Python {platform.python_version()}, "
          f"commit {commit}; load {load0[0]:.2f} at start, {os.getloadavg()[0]:.2f} at end.")
    print()
    print("| what | wall: median [min - max] | goal < 10 s |")
    print("|---|---|---|")
    print(f"| `plan_schedule(paper, {RATE:g} Hz)` in process (h_min 0.5 s, tau_max 4 s; "
          f"{res.evaluations} cost evaluations) "
          f"| {_stat(t_plan)} | {'**yes**' if statistics.median(t_plan) < 10 else 'no'} |")
    print(f"| `plan_schedule(paper, {RATE:g} Hz)` with `--dead-time {DEAD:g}` and h_min 0.1 s "
          f"({res_d.evaluations} evaluations; planned tau {res_d.tau:g} s, counts {res_d.counts}, cost "
          f"{res_d.cost:.4e}) | {_stat(t_dead)} | {'**yes**' if statistics.median(t_dead) < 10 else 'no'} |")
    print(f"| `switchobs plan paper --rate {RATE:g} --json` end to end (+ LMI design, Kalman design, paper's cycles) "
          f"| {_stat(t_cli)} | {'**yes**' if statistics.median(t_cli) < 10 else 'no'} |")
    print()
    print(f"Planned: tau = {res.tau:g} s, h = {', '.join(f'{h:g}' for h in res.h)} s "
          f"(counts {res.counts}), cost {res.cost:.4e} (mean tr P^- over a period, W = I, default noise); "
          f"local minimum: {res.local_minimum}. Kalman certified rate {out['kalman']['certified_rate']:.3g} 1/s; "
          + (f"LMI eta_min {', '.join(f'{e:.3g}' for e in out['lmi']['eta_min'])}, certified rate "
             f"{out['lmi']['certified_rate']:.3g} 1/s." if out["lmi"]["feasible"] else
             f"LMI: infeasible: {out['lmi']['reason']}"))
    print()
    print("| cycle (tau, s) | cost | / planned |")
    print("|---|---|---|")
    print(f"| planned ({res.tau:g}, {res.h[0] / res.tau:g}) | {res.cost:.4e} | 1.000 |")
    for tau, s, c in paper:
        print(f"| paper ({tau:g}, {s:g}) | {c:.4e} | {c / res.cost:.3f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
