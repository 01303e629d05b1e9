#!/usr/bin/env python
"""The estimator's outputs at 32 agents (n = 132), in process: the Python message writers plus
rclpy's serialisation (what ``Publisher.publish(msg)`` does before the middleware) against the
raw writers of :mod:`msg_bridge.raw` (the bytes ``publish(bytes)`` hands over), side by side in
one run (not a test; bench/RESULTS.md).

    python bench/bench_outputs.py [--agents 32] [--repeat 200] [--rounds 5]

Per output and estimate: median CPU time (``time.process_time``) of building the message from
``x`` and ``P`` and serialising it, over interleaved rounds. No DDS: the middleware's own cost
of a publish is the same for both.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from rclpy.serialization import serialize_message

import msg_bridge as mb
from msg_bridge.markers import MarkersWriter, RawMarkersWriter
from msg_bridge.raw import RawLabelledArrayWriter, RawOdometryBatch
from msg_bridge.typed import RawStateEstimateWriter, StateEstimateWriter


def writers(labels: tuple[str, ...]) -> dict:
    """``{output: (python_path, raw_path)}``, each a function of ``(x, stamp, P)`` returning bytes."""
    bodies = mb.bodies(labels)
    frames = [b.name for b in bodies]
    w_state, r_state = mb.LabelledArrayWriter(labels), RawLabelledArrayWriter(labels)
    cov_labels = mb.covariance_labels(labels)
    w_cov, r_cov = mb.LabelledArrayWriter(cov_labels), RawLabelledArrayWriter(cov_labels)
    w_odom = [mb.OdometryWriter(b, "map", c) for b, c in zip(bodies, frames)]
    r_odom = RawOdometryBatch(bodies, "map", frames)
    w_se, r_se = StateEstimateWriter(labels, "map"), RawStateEstimateWriter(labels, "map")
    w_mk, r_mk = MarkersWriter(bodies, "map"), RawMarkersWriter(bodies, "map")
    return {
        "~/state": (lambda x, s, P: serialize_message(w_state.msg(x, s)), lambda x, s, P: r_state.msg(x, s)),
        "~/covariance": (lambda x, s, P: serialize_message(w_cov.msg(P.ravel(), s)),
                         lambda x, s, P: r_cov.msg(P.ravel(), s)),
        f"{len(bodies)} odometries": (lambda x, s, P: [serialize_message(w.msg(x, s, P)) for w in w_odom],
                                      lambda x, s, P: r_odom.msgs(x, s, P)),
        "~/state_estimate": (lambda x, s, P: serialize_message(w_se.msg(x, s, P)), lambda x, s, P: r_se.msg(x, s, P)),
        "~/markers": (lambda x, s, P: serialize_message(w_mk.msg(x, s, P, 0.5, bodies[1].name)),
                      lambda x, s, P: r_mk.msg(x, s, P, 0.5, bodies[1].name)),
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--agents", type=int, default=32)
    ap.add_argument("--repeat", type=int, default=200)
    ap.add_argument("--rounds", type=int, default=5)
    a = ap.parse_args(argv)
    labels = tuple(f"{b}.{q}" for b in ["camera", *(f"agent{k}" for k in range(1, a.agents + 1))]
                   for q in ("p_x", "p_y", "v_x", "v_y"))
    n = len(labels)
    rng = np.random.default_rng(0)
    A = rng.normal(size=(n, n))
    P = A @ A.T
    x = rng.normal(size=n)
    ws = writers(labels)
    times: dict[tuple[str, int], list[float]] = {}
    for _ in range(a.rounds):
        for name, paths in ws.items():
            for k, f in enumerate(paths):
                reps = max(a.repeat // (10 if name == "~/markers" and k == 0 else 1), 5)
                t0 = time.process_time()
                for i in range(reps):
                    f(x, 1_700_000_000_000_000_000 + i, P)
                times.setdefault((name, k), []).append((time.process_time() - t0) / reps)
    print(f"Command: `OPENBLAS_NUM_THREADS=1 python bench/bench_outputs.py --agents {a.agents} "
          f"--repeat {a.repeat} --rounds {a.rounds}` (n = {n})\n")
    print("| output, per estimate | Python message + serialisation | raw bytes | ratio |")
    print("|---|---|---|---|")
    for name in ws:
        py, raw = (float(np.median(times[(name, k)])) * 1e6 for k in (0, 1))
        print(f"| {name} | {py:.0f} us | {raw:.0f} us | {raw / py:.2f}x |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
