"""Benchmark of attribution and bounds across clocks (not a test): camera_sim and the estimator
over DDS on this machine's system clock, camera_sim's camera clock shifted by ``stamp_offset_ms``
against its targets', its channel message sent after each tick's poses (the first pose of a new
channel before its channel message, as two computers that tick independently send them). Every
published estimate is checked against the published truth at its stamp.

``python bench/bench_clocks.py [--seconds 10]``

Conditions, side by side in one run: the channel as ``std_msgs/UInt8`` (attributed by the
publishers' source timestamps) and as ``switchobs_msgs/ActiveChannel`` (by the stamps), without and
with a camera clock offset, with ``clock_tolerance_ms`` declared or not. Then, in process, the
published exact bound against the tolerance (the paper's system and LMI gains, 100 Hz, samples
stamped the tolerance early).

Writes a Markdown section to stdout (recorded in bench/RESULTS.md).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

#: (name, channel type, camera offset ms, clock_tolerance_ms)
CONDITIONS = (
    ("UInt8, channel after poses", "std_msgs/msg/UInt8", 0.0, 0.0),
    ("ActiveChannel, channel after poses", "switchobs_msgs/msg/ActiveChannel", 0.0, 0.0),
    ("ActiveChannel, camera +2 ms, tolerance 3 ms", "switchobs_msgs/msg/ActiveChannel", 2.0, 3.0),
    ("ActiveChannel, camera +50 ms, tolerance 3 ms", "switchobs_msgs/msg/ActiveChannel", 50.0, 3.0),
    ("ActiveChannel, camera +50 ms, no tolerance declared", "switchobs_msgs/msg/ActiveChannel", 50.0, 0.0),
)


def dds(seconds: float) -> list[str]:
    from switchobs_core.design.lmi import design_table
    from switchobs_core.model.scenarios import load_system
    from switchobs_core.model.schedule import Cycle
    from tools import demo

    d = tempfile.mkdtemp()
    table = str(design_table(load_system("paper"), [Cycle.from_ts(2.0, 0.6)], delta=0.99).save(d + "/p.json"))
    rows = ["| condition | estimates (truths) | compared at a truth stamp | with a valid bound | above a valid bound "
            "| final error / bound |", "|---|---|---|---|---|---|"]
    for name, kind, off, tol in CONDITIONS:
        res = demo.run("periodic", duration=seconds, time_scale=1.0, init="paper", gain_table=table, quiet=True,
                       extra_camera={"stamp_offset_ms": off, "channel_last": True, "publish_clock": False,
                                     "channel_type": kind},
                       extra_estimator={"clock_tolerance_ms": tol})
        err, ex = res["err"], res["exact"]
        valid = ex > 0
        above = valid & (err > ex * (1 + 1e-9))
        rows.append(f"| {name} | {res['n_state']} ({res['n_truth']}) | {len(err)} | {int(valid.sum())} | "
                    f"**{int(above.sum())}**{f' (up to {np.max(err[above] / ex[above]):.3g}x)' if above.any() else ''}"
                    f" | {err[-1]:.3g} m / {ex[-1]:.3g} |")
        print(rows[-1], file=sys.stderr, flush=True)
    return rows


def growth() -> list[str]:
    from scipy.linalg import expm

    from switchobs_core.design.lmi import design_table
    from switchobs_core.model.scenarios import load_system
    from switchobs_core.model.schedule import Cycle, PeriodicSchedule
    from switchobs_core.runtime.observer import SwitchedObserver

    sys_ = load_system("paper")
    cyc = Cycle.from_ts(2.0, 0.6)
    table = design_table(sys_, [cyc], delta=0.99)
    x0 = np.array([0.0, 0.0, 0.2, 0.1, 3.0, 1.0, -0.1, 0.0, -2.0, 2.0, 0.1, 0.0])
    rows = ["| clock tolerance | exact bound at 4 s | 8 s | 16 s | largest error / bound |", "|---|---|---|---|---|"]
    for d in (0.0, 0.0005, 0.001, 0.002, 0.005, 0.01):
        obs = SwitchedObserver(sys_, table, mode="periodic", cycles=[cyc], x0=x0 + 0.25, e0=1.0)
        if d:
            obs.rounding.clock(d)
        sched = PeriodicSchedule(cyc)
        at, worst = {}, 0.0
        for k in range(1, 1601):
            t = k / 100
            c = int(sched.channel_at(t))
            obs.update(t, c, sys_.C[c - 1] @ (expm(sys_.A * (t + d)) @ x0))
            b = obs.envelope().exact_bound
            worst = max(worst, float(np.linalg.norm(obs.x_hat - expm(sys_.A * t) @ x0)) / b)
            if k in (400, 800, 1600):
                at[k] = b
        rows.append(f"| {d * 1e3:g} ms | {at[400]:.3g} | {at[800]:.3g} | {at[1600]:.3g} | {worst:.3g} |")
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seconds", type=float, default=10.0)
    a = ap.parse_args()
    print("### Over DDS: camera_sim and the estimator, channel message after the poses\n")
    print("\n".join(dds(a.seconds)))
    print("\n### The exact bound against the declared clock tolerance (in process)\n")
    print("\n".join(growth()))


if __name__ == "__main__":
    main()
