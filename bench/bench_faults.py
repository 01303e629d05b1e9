#!/usr/bin/env python
"""The estimator's minor page faults per sample at 32 agents (n = 132), in process: camera_sim's stream
through the node's input handler and outputs (``bench/bench_pipeline.py``'s stand-in node, publishers
that drop the bytes), glibc's malloc as it starts or set at the child's start (not a test;
bench/RESULTS.md).

    python bench/bench_faults.py [--table /tmp/boot/k32v4.npz] [--seconds 100] [--variants default,kept,trim]

Variants, each a child process of its own (malloc's settings are the process's): ``default`` (glibc's
own, adjusted thresholds), ``kept`` (:func:`switchobs_ros.heap.keep_heap`, what the estimators'
console scripts set), ``trim`` (only the trim threshold set, 64 MiB: glibc's adjustment off, the mmap
threshold left at 128 KiB), ``hugetlb`` (``GLIBC_TUNABLES=glibc.malloc.hugetlb=1``: the heap in
transparent huge pages). Reported per window: minor faults per sample (``getrusage``), user and system
CPU per sample, the process's RSS at the window's ends. Windows: while the Kalman table's phases are
read for the first time (its start-up segment and first period: a version-4 table reads each phase's
prior on first use, :mod:`switchobs_core.table.rows`) and after every phase is in memory; ``--every``
the outputs' decimation (the live benchmark's). Without the middleware: rclpy's copy of a published
message and the middleware's buffers are not here (``bench/bench_live_scale.py --threads`` counts the
node's faults through DDS).
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "bench"))

VARIANTS = {"default": {}, "kept": {}, "trim": {}, "hugetlb": {"GLIBC_TUNABLES": "glibc.malloc.hugetlb=1"}}


def child(a) -> dict:
    """One variant: the stream through the node's handler; per-tick faults and CPU (JSON on stdout)."""
    if a.variant == "kept":
        from switchobs_ros.heap import keep_heap
        assert keep_heap() is not None, "keep_heap changed nothing (not glibc, or MALLOC_* set)"
    elif a.variant == "trim":
        import ctypes
        ctypes.CDLL(None).mallopt(-1, 64 << 20)         # M_TRIM_THRESHOLD alone
    import gc

    from bench_pipeline import _bench_node, deliver, stream_inputs

    from switchobs_core.threads import single_threaded_blas
    from switchobs_ros.config import params_from_file
    single_threaded_blas()
    s = np.load(a.stream)
    agents = a.agents
    every = {k: int(v) for k, v in (kv.split("=") for kv in a.every.split(",") if kv)}
    cfg = params_from_file(overrides={"system": str(s["system"]), "gain_table": a.table, "schedule.mode": "periodic",
                                      "schedule.h": tuple([1.0] * agents), "e0": 1e3, "max_abs_value": 1e12,
                                      **{f"output.{k}_every": v for k, v in every.items()}})
    node, clock = _bench_node(cfg)
    pl = node.pipeline
    stamps, tick_of, topics = s["stamps"], s["tick_of"], s["topics"]
    msgs, handlers, seq = stream_inputs(s, node)
    n = len(stamps)
    faults, user, system, rss = np.zeros(n), np.zeros(n), np.zeros(n), np.zeros(n)
    gc.freeze()
    i = 0
    for k in range(n):
        r0 = resource.getrusage(resource.RUSAGE_SELF)
        while i < len(topics) and tick_of[i] == k:
            deliver(handlers, seq, clock, topics[i], msgs[i], int(stamps[k]) + 100_000 * (1 + i % 3))
            i += 1
        r1 = resource.getrusage(resource.RUSAGE_SELF)
        faults[k] = r1.ru_minflt - r0.ru_minflt
        user[k], system[k] = r1.ru_utime - r0.ru_utime, r1.ru_stime - r0.ru_stime
        rss[k] = int(Path("/proc/self/statm").read_text().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20
    if pl.errors or sum(pl.rejected.values()):
        sys.exit(f"the stream was not answered cleanly: {dict(pl.rejected)}")
    phases = len(pl.observer.gains.kalman.startup) + len(pl.observer.gains.kalman.periodic)
    return {"answers": int(pl.updates), "phases": phases, "faults": faults.tolist(), "user": user.tolist(),
            "system": system.tolist(), "rss": rss.tolist()}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--agents", type=int, default=32)
    ap.add_argument("--rate", type=float, default=50.0)
    ap.add_argument("--seconds", type=float, default=100.0, help="the stream's length (s)")
    ap.add_argument("--table", default="/tmp/boot/k32v4.npz", help="the Kalman table of the model and schedule")
    ap.add_argument("--variants", default="default,kept,trim", help=f"of {', '.join(VARIANTS)}")
    ap.add_argument("--every", default="odometry=5,covariance=5,typed=5", help="output.<K>_every values")
    ap.add_argument("--variant", default=None, help=argparse.SUPPRESS)
    ap.add_argument("--stream", type=Path, default=None, help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    if a.variant is not None:
        print(json.dumps(child(a)))
        return 0
    from bench_pipeline import make_stream

    from switchobs_ros.heap import user_configured
    base = {k: v for k, v in os.environ.items() if not user_configured({k: v})}
    base.update(OPENBLAS_NUM_THREADS="1", PYTHONPATH=str(REPO))
    res = {}
    with tempfile.TemporaryDirectory(prefix="bench_faults_") as tmp:
        stream = Path(tmp) / "stream.npz"
        make_stream(a.agents, a.rate, a.seconds, stream)
        for v in a.variants.split(","):
            cmd = [sys.executable, str(Path(__file__).resolve()), "--variant", v, "--stream", str(stream),
                   "--agents", str(a.agents), "--table", a.table, "--every", a.every]
            r = subprocess.run(cmd, env=dict(base, **VARIANTS[v]), capture_output=True, text=True)
            if r.returncode:
                sys.exit(f"variant {v} failed:\n{r.stderr[-4000:]}")
            res[v] = json.loads(r.stdout.strip().splitlines()[-1])
    first = next(iter(res.values()))
    n, phases = len(first["faults"]), first["phases"]
    windows = {"first visits": (int(a.rate), min(phases, n)), "table in memory": (min(phases + int(a.rate), n), n)}
    print(f"Command: `OPENBLAS_NUM_THREADS=1 python bench/bench_faults.py --agents {a.agents} --seconds {a.seconds:g} "
          f"--table {a.table} --variants {a.variants} --every {a.every}` (n = {4 * (a.agents + 1)}, {phases} stored "
          f"phases; load {os.getloadavg()[0]:.1f} after)\n")
    print("| variant | window (samples) | minor faults per sample | user CPU per sample | system CPU per sample "
          "| RSS at its ends |")
    print("|---|---|---|---|---|---|")
    for v, r in res.items():
        for w, (lo, hi) in windows.items():
            if hi <= lo:
                continue
            f, u, st, rss = (np.asarray(r[k][lo:hi]) for k in ("faults", "user", "system", "rss"))
            print(f"| {v} | {w} ({lo}-{hi}) | {f.mean():.2f} | {u.mean() * 1e3:.3f} ms | {st.mean() * 1e3:.3f} ms "
                  f"| {rss[0]:.0f} -> {rss[-1]:.0f} MiB |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
