#!/usr/bin/env python
"""A digest of every message the estimator publishes on camera_sim's stream, in process, per tree (not a
test; a check that a change keeps the published bytes, beside the speed benches; bench/RESULTS.md).

    python bench/publish_digest.py --before /tmp/base [--seconds 40] [--drop 0.1] [--table /tmp/boot/k32v5.npz]

Each tree (this checkout and ``--before``) runs in a child of its own: the node's behaviour on
``bench_pipeline.py``'s stand-in (every output listened, the goal's output rates), fed the stream of
``bench_pipeline.py --agents N`` for ``--seconds``; ``--drop F`` drops that fraction of the ticks after the
first second (both poses, the channel message kept; a fixed seed), which sends the Kalman table through
its missing-sample path. Every serialised write (state, envelope, covariance, odometries, the typed
estimate, markers) enters a SHA-256 with its topic; a message object (the typed bounds) enters as its
``repr`` (its fields: rclpy's serialisation leaves the padding bytes as they were in memory, so two runs of
one tree differ there). Printed per tree: the digest, the messages, the answers.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]


def run_child(a) -> dict:
    """One tree: the stream through the node's input handler; the digest of what it published."""
    sys.path.insert(0, str(a.child))
    sys.path.insert(0, str(REPO / "bench"))
    import bench_pipeline as bp

    from switchobs_core.threads import single_threaded_blas
    from switchobs_ros.config import params_from_file

    single_threaded_blas()
    s = np.load(a.stream)
    every = {"envelope": 1, "odometry": 5, "covariance": 5, "typed": 5, "markers": 10}
    cfg = params_from_file(overrides={"system": str(s["system"]), "gain_table": a.table,
                                      "schedule.mode": "periodic", "schedule.h": tuple([1.0] * a.agents),
                                      "e0": 1e3, "max_abs_value": 1e12,
                                      **{f"output.{k}_every": v for k, v in every.items()}})
    h = hashlib.sha256()
    count = [0]

    def publish_raw(self, data) -> None:
        h.update(self.topic_name.encode())
        h.update(bytes(data))
        count[0] += 1

    def publish(self, msg) -> None:
        h.update(self.topic_name.encode())
        h.update(repr(msg).encode())
        count[0] += 1

    bp._Publisher.publish_raw, bp._Publisher.publish = publish_raw, publish
    node, clock = bp._bench_node(cfg)
    import switchobs_core
    assert switchobs_core.__file__.startswith(str(a.child)), switchobs_core.__file__
    pl = node.pipeline
    msgs, handlers, seq = bp.stream_inputs(s, node)
    topics, tick_of, stamps = s["topics"], s["tick_of"], s["stamps"]
    n_ticks = int(round(a.seconds * a.rate))
    dropped = np.random.default_rng(7).random(n_ticks) < a.drop
    dropped[:int(a.rate)] = False
    i = 0
    for k in range(n_ticks):
        while i < len(topics) and tick_of[i] == k:
            if not (dropped[k] and topics[i] != pl.channel_topic):
                bp.deliver(handlers, seq, clock, topics[i], msgs[i], int(stamps[k]) + 100_000 * (1 + i % 3))
            i += 1
    return {"digest": h.hexdigest()[:16], "messages": count[0], "answers": int(pl.updates), "errors": int(pl.errors)}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--agents", type=int, default=32)
    ap.add_argument("--rate", type=float, default=50.0)
    ap.add_argument("--seconds", type=float, default=40.0)
    ap.add_argument("--drop", type=float, default=0.0)
    ap.add_argument("--table", default="/tmp/boot/k32v5.npz")
    ap.add_argument("--before", type=Path, default=None, help="a checkout to compare with")
    for hidden in ("--stream", "--child"):      # a child's: the stream's file, its tree
        ap.add_argument(hidden, type=Path, default=None, help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    if a.child is None:
        return compare(a)
    print(json.dumps(run_child(a)))
    return 0


def compare(a: argparse.Namespace) -> int:
    """The trees' digests on one stream, side by side."""
    sys.path.insert(0, str(REPO / "bench"))
    import bench_pipeline as bp
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1")
    out = {}
    with tempfile.TemporaryDirectory(prefix="publish_digest_") as tmp:
        stream = Path(tmp) / "stream.npz"
        bp.make_stream(a.agents, a.rate, a.seconds, stream)
        for name, tree in [("this", REPO)] + ([("before", a.before.resolve())] if a.before else []):
            cmd = [sys.executable, str(Path(__file__).resolve()), "--child", str(tree), "--stream", str(stream),
                   "--agents", str(a.agents), "--rate", str(a.rate), "--seconds", str(a.seconds),
                   "--drop", str(a.drop), "--table", a.table]
            r = subprocess.run(cmd, env=dict(env, PYTHONPATH=str(tree)), capture_output=True, text=True)
            if r.returncode:
                sys.exit(f"child {tree} failed:\n{r.stderr[-4000:]}")
            out[name] = json.loads(r.stdout.strip().splitlines()[-1])
    for name, r in out.items():
        print(f"{name}: sha256 {r['digest']}, {r['messages']} messages, {r['answers']} answers, {r['errors']} errors")
    if len(out) == 2:
        print("the same bytes" if out["this"]["digest"] == out["before"]["digest"] else "**the bytes differ**")
    return 0


if __name__ == "__main__":
    sys.exit(main())
