"""Benchmark of the bag tools (not a test): offline estimate throughput vs live replay.

``python bench/bench_bag.py [--duration 30] [--reps 7] [--live-reps 1] [--no-live]``

1. A bag of the paper's scenario (12 states, 100 Hz, periodic (2 s, 0.6), noise 0.01) from
   ``switchobs_bag generate`` (mcap; the same data as sqlite3).
2. Offline ``estimate`` over it, ``--reps`` times per variant; the median messages per second,
   counting every message of the bag (5 per tick: /clock, channel, two poses, truth):
   * the estimation loop alone (messages already read; no output),
   * the loop writing the estimates bag with the inputs copied (the default of the CLI),
   * end to end: open, read, estimate, write the bag and the CSV, close (what a user waits for).
3. Live replay at the bag's own rate (``play --rate 1``) into an estimator process over DDS with
   sim time, recorded by ``switchobs_bag record``; wall time of the playback, and a check that
   the live estimates equal the offline ones. Ratio = live wall time / offline end-to-end time.

Writes a Markdown section to stdout (recorded in bench/RESULTS.md).
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


def _cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--duration", type=float, default=30.0, help="simulated seconds of the bag (default 30)")
    ap.add_argument("--reps", type=int, default=7)
    ap.add_argument("--live-reps", type=int, default=1)
    ap.add_argument("--no-live", action="store_true")
    a = ap.parse_args(argv)

    from switchobs_core.design.lmi import design_table
    from switchobs_core.model.scenarios import load_system
    from switchobs_core.model.schedule import Cycle
    from switchobs_core.threads import single_threaded_blas
    from switchobs_ros.bag.estimate import estimate, estimator_params
    from switchobs_ros.bag.generate import GenerateConfig, generate

    single_threaded_blas()
    work = Path(tempfile.mkdtemp(prefix="switchobs_bench_bag_"))
    table = design_table(load_system("paper"), [Cycle.from_ts(2.0, 0.6)], delta=0.99).save(work / "gains.json")
    params = {"gain_table": str(table), "e0": 5.0}
    cfg = estimator_params(overrides=params)
    t = time.perf_counter()
    gen = generate(work / "in", GenerateConfig(duration=a.duration, noise_std=0.01), "mcap")
    t_gen = time.perf_counter() - t
    generate(work / "in_sql", GenerateConfig(duration=a.duration, noise_std=0.01), "sqlite3")
    n_msgs = gen["messages"]

    rows = {}

    def rep(name, fn):
        vals = []
        for k in range(a.reps):
            vals.append(fn(k))
        rows[name] = statistics.median(vals)

    rep("loop, no output (mcap)", lambda k: n_msgs / estimate(work / "in", cfg).seconds)
    rep("loop, writing the estimates bag + inputs (mcap)",
        lambda k: n_msgs / estimate(work / "in", cfg, out=work / f"o{k}").seconds)

    def e2e(src, k, tag):
        t0 = time.perf_counter()
        estimate(work / src, cfg, out=work / f"{tag}{k}", csv=work / f"{tag}{k}.csv")
        return n_msgs / (time.perf_counter() - t0)

    rep("end to end: read + estimate + bag + CSV (mcap)", lambda k: e2e("in", k, "e"))
    rep("end to end: read + estimate + bag + CSV (sqlite3)", lambda k: e2e("in_sql", k, "s"))
    t_off = n_msgs / rows["end to end: read + estimate + bag + CSV (mcap)"]
    off = estimate(work / "in", cfg)

    live_walls, live_diff, live_n = [], [], []
    if not a.no_live:
        from switchobs_ros.bag.io import BagIn, deserialize
        from tools.domain import claim_domain, localhost_env
        from tools.live_replay import live_replay

        lease = claim_domain()
        os.environ.update(localhost_env(lease.domain_id))
        from std_msgs.msg import Float64MultiArray

        import msg_bridge as mb
        for k in range(a.live_reps):
            res = live_replay(work / "in", work / f"rec{k}", work / f"live{k}", params, rate=1.0)
            live_walls.append(res["wall"])
            with BagIn(work / f"rec{k}") as bag:
                st = [mb.unpack_labelled(deserialize(m, Float64MultiArray))
                      for m in bag.messages(["/estimator/state"], order="file")]
            live_n.append(len(st))
            if [s.stamp_ns for s in st] == off.stamps.tolist():
                live_diff.append(float(np.abs(np.array([s.values for s in st]) - off.x_hat).max()))
            else:
                live_diff.append(float("nan"))
        lease.release()

    load = os.getloadavg()
    print("### Bag tools: offline estimate vs live replay (bench/bench_bag.py)\n")
    print(f"{time.strftime('%Y-%m-%d %H:%M')}, {platform.node()}, nproc {os.cpu_count()}, {_cpu_model()}, "
          f"Python {platform.python_version()}; load average at the end {load[0]:.2f}, {load[1]:.2f}, {load[2]:.2f} "
          "(the machine is shared with concurrent sessions).\n")
    print(f"Bag: the paper's scenario (n = 12 states, N = 2), periodic (2 s, 0.6), 100 Hz, noise 0.01, "
          f"{a.duration:g} s: {gen['ticks']} ticks, {n_msgs} messages (/clock, channel, camera pose, target pose, "
          f"truth per tick), {gen['ticks']} estimates. `generate` took {t_gen:.2f} s "
          f"({a.duration / t_gen:.0f}x real time).\n")
    print(f"| offline estimate (median of {a.reps}) | messages/s | estimates/s | goal >= 20 000 msg/s |")
    print("|---|---:|---:|:---:|")
    for name, v in rows.items():
        print(f"| {name} | {v:,.0f} | {v * gen['ticks'] / n_msgs:,.0f} | {'yes' if v >= 20000 else 'no'} |")
    if live_walls:
        w = statistics.median(live_walls)
        print(f"\nLive replay at the bag's own rate (`play --rate 1`, estimator over DDS with sim time, "
              f"{a.live_reps} run(s)): median playback wall time {w:.2f} s for {a.duration:g} s of data; "
              f"estimates recorded {live_n}; max |live - offline| over x_hat: "
              f"{', '.join(f'{d:.1e}' for d in live_diff)} (nan: stamps differ).\n")
        print(f"**Offline end to end is {w / t_off:,.0f}x faster than live replay at the bag's rate** "
              f"({t_off:.3f} s vs {w:.2f} s).")
    return 0


if __name__ == "__main__":
    sys.exit(main())
