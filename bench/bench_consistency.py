"""What the measurement seam costs per sample: the estimator's pipeline (the code the node runs on
every message) over the same recorded stream, side by side in one process, interleaved rounds,
CPU time, medians:

* ``arrival``: no source timestamps (arrival order decides the channel);
* ``source``: source timestamps and the 50 ms reorder window (the live node's path);
* ``source+check``: the same with the innovation consistency test on every sample
  (``consistency.check: always``).

``python bench/bench_consistency.py [--seconds 60] [--rounds 5]``; results in bench/RESULTS.md.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
if str(REPO) not in sys.path:
    sys.path.insert(0, str(REPO))

from bench_design import machine_info  # noqa: E402

from switchobs_core.threads import single_threaded_blas  # noqa: E402
from switchobs_ros.bag.estimate import estimator_params  # noqa: E402
from switchobs_ros.bag.generate import GenerateConfig, scenario_ticks  # noqa: E402
from switchobs_ros.pipeline import EstimatorPipeline  # noqa: E402

CONFIGS = {"arrival": ("never", False), "source": ("never", True), "source+check": ("always", True)}


def _stream(seconds: float) -> list[tuple[int, str, object]]:
    """The paper scene's input messages in camera_sim's publishing order: (stamp, topic, message)."""
    out = []
    for stamp, msgs in scenario_ticks(GenerateConfig(duration=seconds, rate=100.0)):
        out += [(stamp, t[1:], m) for t, m in msgs if t not in ("/clock", "/sim/truth")]
    return out


def _run(stream, table: str, check: str, with_src: bool) -> tuple[float, int]:
    pl = EstimatorPipeline.from_params(estimator_params(overrides={"gain_table": table, "e0": 5.0,
                                                                   "consistency.check": check}))
    n = 0
    src = 10**15
    t = time.process_time()
    for k, (stamp, topic, msg) in enumerate(stream):
        src += 1000
        n += len(pl.on_message(topic, msg, stamp, k * 1e-3, src if with_src else None))
    n += len(pl.flush_all())
    return time.process_time() - t, n


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seconds", type=float, default=60.0)
    ap.add_argument("--rounds", type=int, default=5)
    a = ap.parse_args(argv)
    single_threaded_blas()
    from switchobs_core.design.lmi import design_table
    from switchobs_core.model.scenarios import load_system
    from switchobs_core.model.schedule import Cycle

    tmp = Path(tempfile.mkdtemp())
    design_table(load_system("paper"), cycles=[Cycle.from_ts(2.0, 0.6)], delta=0.99).save(tmp / "t.json")
    stream = _stream(a.seconds)
    times: dict[str, list[float]] = {k: [] for k in CONFIGS}
    answers = {}
    for _ in range(a.rounds):
        for name, (check, src) in CONFIGS.items():
            dt, n = _run(stream, str(tmp / "t.json"), check, src)
            times[name].append(dt / n * 1e6)
            answers[name] = n
    base = statistics.median(times["arrival"])
    info = machine_info()
    print(f"{info['date']}, {info['cpu']}, {info['nproc']} cores; paper scene, 100 Hz, {a.seconds:g} s, "
          f"{a.rounds} interleaved rounds, CPU time per answered sample (median)")
    print("| path | us per sample | ratio to arrival order | samples answered |")
    print("|---|---:|---:|---:|")
    for name in CONFIGS:
        m = statistics.median(times[name])
        print(f"| {name} | {m:.1f} | {m / base:.2f} | {answers[name]} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
