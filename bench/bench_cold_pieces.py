"""The core's CPU per sample at 32 agents (n = 132) with cold caches, piece by piece: the
screening's calls (the prior, the innovation test, the bias test) and the update and envelope,
each tick after writing every cache line of an 8 MiB buffer (untimed), as the node's thread
finds its caches after 20 ms of other processes' work (bench/RESULTS.md, branch ``cold``).

    OPENBLAS_NUM_THREADS=1 python bench/bench_cold_pieces.py [--before /tmp/base9] [--rounds 3] [--ticks 900]

Each tree runs in its own child, the trees interleaved round by round; each child takes the first
``--ticks`` of camera_sim's stream (all first visits of the Kalman table: its rows read and
verified then) through ``SwitchedObserver.prior``, ``InnovationTest.check``, ``Recovery.before``
(with the prediction shared where the tree takes it, as ``Screening.admit``), ``update`` and
``envelope``, and reports the mean thread CPU of each (the first 20 ticks left out) and, with
``--fine``, the own CPU of the functions below them (``bench/phases.py``'s wrappers: each adds
about 1.5 us).
"""

from __future__ import annotations

import argparse
import inspect
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]

#: (module, attribute path, label) of the functions the fine split wraps (their own CPU per tick).
FINE = (
    ("switchobs_core.runtime.observer", "SwitchedObserver.prior", "prior: SwitchedObserver.prior"),
    ("switchobs_core.runtime.observer", "SwitchedObserver._held_step", "prior: _held_step (x at t)"),
    ("switchobs_core.bounds.rigorous", "RoundingBound.propagated", "prior: RoundingBound.propagated"),
    ("switchobs_core.bounds.rigorous", "open_loop_product", "prior: open_loop_product (Z = E S E', n x n)"),
    ("switchobs_core.numerics.rounding", "ErrorEllipsoid.pending", "prior: ErrorEllipsoid.pending (plan)"),
    ("switchobs_core.numerics.rounding", "ErrorEllipsoid._block", "innovation: ErrorEllipsoid._block"),
    ("switchobs_core.runtime.consistency", "InnovationTest.check", "innovation: InnovationTest.check"),
    ("switchobs_core.runtime.recovery", "Recovery.before", "bias: Recovery.before"),
    ("switchobs_core.runtime.observer", "SwitchedObserver.prior_covariance", "bias: prior_covariance"),
    ("switchobs_core.table.kalman", "KalmanPhase.P_block", "bias: KalmanPhase.P_block"),
    ("switchobs_core.table.rows", "LazyRows.row", "bias: LazyRows.row (pread, SHA-256, isfinite)"),
    ("switchobs_core.runtime.bias", "BiasDetector.update", "bias: BiasDetector.update"),
    ("switchobs_core.runtime.observer", "SwitchedObserver.update", "update: SwitchedObserver.update"),
    ("switchobs_core.runtime.error_maps", "FusedMap.apply", "update: FusedMap.apply"),
    ("switchobs_core.bounds.rigorous", "RoundingBound.fused", "update: RoundingBound.fused"),
    ("switchobs_core.bounds.kalman_map", "KalmanMap.sandwich", "update: KalmanMap.sandwich (M Z M')"),
    ("switchobs_core.numerics.rounding", "ErrorEllipsoid.propagate_product", "update: propagate_product"),
    ("switchobs_core.numerics.rounding", "ErrorEllipsoid._apply", "update: ErrorEllipsoid._apply (n x n)"),
    ("switchobs_core.runtime.families.kalman", "KalmanTableGains._locked", "update: KalmanTableGains._locked"),
    ("switchobs_core.runtime.observer", "SwitchedObserver.envelope", "envelope: SwitchedObserver.envelope"),
    ("switchobs_core.bounds.rigorous", "RoundingBound.bounds", "envelope: RoundingBound.bounds"),
)
PIECES = ("prior", "innovation", "bias", "update", "envelope")


def run_child(a: argparse.Namespace) -> dict:
    """One tree: the pieces' mean CPU per tick (us), and with ``--fine`` the wrapped functions' own."""
    sys.path.insert(0, str(a.child))
    sys.path.insert(0, str(REPO / "bench"))
    import importlib

    import bench_pipeline as bp

    from switchobs_core.runtime.recovery import Recovery
    from switchobs_core.threads import single_threaded_blas
    from switchobs_ros.config import params_from_file

    single_threaded_blas()
    if a.fine:
        import phases as ph
        for mod_name, path, label in FINE:
            owner = importlib.import_module(mod_name)
            *owners, name = path.split(".")
            for o in owners:
                owner = getattr(owner, o)
            ph._patch(owner, name, label)
    s = np.load(a.stream)
    cfg = params_from_file(overrides={"system": str(s["system"]), "gain_table": a.table,
                                      "schedule.mode": "periodic", "schedule.h": tuple([1.0] * 32),
                                      "e0": 1e3, "max_abs_value": 1e12})
    node, _ = bp._bench_node(cfg)
    import switchobs_core
    assert switchobs_core.__file__.startswith(str(a.child)), switchobs_core.__file__
    pl = node.pipeline
    obs, scr = pl.observer, pl.screening
    obs.reset(pl.x0, 0.0)
    rec = Recovery(obs, labels=scr.labels)
    shared = "x_p" in inspect.signature(rec.before).parameters
    y, ch, stamps = s["y"], s["channels"], s["stamps"]
    junk = np.zeros(8 * 2**20, dtype=np.uint8)
    tt = time.thread_time_ns
    cost = {k: [] for k in PIECES}
    import gc
    gc.freeze()
    skip = 20
    for k in range(min(a.ticks, len(stamps))):
        if k == skip and a.fine:
            ph._own.clear()
            ph._calls.clear()
        junk[::64] += 1         # every cache line written: other processes' work between ticks
        t = (int(stamps[k]) - int(stamps[0])) * 1e-9
        c = int(ch[k])
        t0 = tt()
        with np.errstate(all="ignore"):
            prior = obs.prior(t, lazy=True)
        t1 = tt()
        scr.innovation.check(prior, c, None, y[k])
        t2 = tt()
        rec.before(t, c, None, y[k], *((prior[0],) if shared else ()))
        t3 = tt()
        obs.update(t, c, y[k])
        t4 = tt()
        obs.envelope()
        t5 = tt()
        if k >= skip:
            for key, v in zip(PIECES, (t1 - t0, t2 - t1, t3 - t2, t4 - t3, t5 - t4)):
                cost[key].append(v / 1e3)
    ticks = len(cost["prior"])
    out = {"pieces": {k: statistics.fmean(v) for k, v in cost.items()}}
    if a.fine:
        out["fine"] = {k: ph._own[k] / 1e3 / ticks for k in ph._own}
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--table", default="/tmp/boot/k32v4.npz")
    ap.add_argument("--before", type=Path, default=None, help="a checkout to compare with")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--ticks", type=int, default=900)
    ap.add_argument("--fine", action="store_true", help="also the own CPU of the functions below the pieces")
    ap.add_argument("--stream", type=Path, default=None, help=argparse.SUPPRESS)
    ap.add_argument("--child", type=Path, default=None, help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    if a.child is not None:
        print(json.dumps(run_child(a)))
        return 0
    sys.path.insert(0, str(REPO / "bench"))
    import bench_pipeline as bp
    trees = [("this", REPO)] + ([("before", a.before.resolve())] if a.before else [])
    got: dict = {name: [] for name, _ in trees}
    with tempfile.TemporaryDirectory(prefix="bench_cold_") as tmp:
        stream = Path(tmp) / "stream.npz"
        bp.make_stream(32, 50.0, a.ticks / 50.0 + 1.0, stream)
        for _ in range(a.rounds):
            for name, tree in trees:
                cmd = [sys.executable, str(Path(__file__).resolve()), "--child", str(tree), "--stream", str(stream),
                       "--table", a.table, "--ticks", str(a.ticks), *(["--fine"] if a.fine else [])]
                r = subprocess.run(cmd, env=dict(os.environ, OPENBLAS_NUM_THREADS="1", PYTHONPATH=str(tree)),
                                   capture_output=True, text=True)
                if r.returncode:
                    sys.exit(f"child {tree} failed:\n{r.stderr[-4000:]}")
                got[name].append(json.loads(r.stdout.strip().splitlines()[-1]))
    print(f"Cold caches (8 MiB written between ticks), mean thread CPU per tick (us), median of {a.rounds} "
          f"interleaved rounds [min - max], {a.ticks} ticks, load {os.getloadavg()[0]:.1f}:\n")
    paired = len(trees) > 1
    tail = " | this / before (paired rounds) |" if paired else " |"
    print("| piece | " + " | ".join(name for name, _ in trees) + tail)
    print("|---|" + "---|" * (len(trees) + paired))
    for key in (*PIECES, "total"):
        cells = []
        vals = {}
        for name, _ in trees:
            v = vals[name] = [sum(g["pieces"].values()) if key == "total" else g["pieces"][key] for g in got[name]]
            cells.append(f"{statistics.median(v):.1f} [{min(v):.1f} - {max(v):.1f}]")
        if paired:      # each round's ratio (the two children ran back to back): the load's drift cancels
            r = [x / y for x, y in zip(vals["this"], vals["before"])]
            cells.append(f"{statistics.median(r):.3f} [{min(r):.3f} - {max(r):.3f}]")
        print(f"| {key} | " + " | ".join(cells) + " |")
    if a.fine:
        labels = sorted({k for g in got[trees[0][0]] for k in g["fine"]}, key=lambda k: FINE.index(
            next(f for f in FINE if f[2] == k)))
        print("\nOwn CPU of the functions below (us per tick, median of the rounds):\n")
        print("| function | " + " | ".join(name for name, _ in trees) + " |")
        print("|---|" + "---|" * len(trees))
        for k in labels:
            print(f"| {k} | " + " | ".join(f"{statistics.median(g['fine'].get(k, 0.0) for g in got[name]):.1f}"
                                           for name, _ in trees) + " |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
