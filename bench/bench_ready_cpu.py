#!/usr/bin/env python
"""CPU to "ready" of the 32-agent estimator's start, read inside each process, beside other checkouts and
the bare rclpy node.

    python bench/bench_ready_cpu.py [--rounds 9] [--before DIR] [--table32 FILE] [--table32-before FILE]

Each round starts, in turn (order rotated), this checkout's estimator as its console script does
(``switchobs_ros.entry.estimator``, ``camera_agents`` M = 32, every h = 1 s, the Kalman table), the
``--before`` checkout's the same way, and the bare republisher of ``bench/bench_node.py``; each process
prints ``time.process_time()`` (user + system CPU of all its threads, the interpreter's start and its
re-exec by the environment included) at the moment it logs "ready" (``EstimatorMixin._ready_log``,
``bare_republisher ready``) and exits. No DDS peer is needed: "ready" comes before any message. Printed:
per node the median and range, and the medians of the per-round ratios to the bare node. What
``bench/bench_startup.py`` reads from ``/proc`` when it sees the log line may include CPU spent after
"ready" (the bench's own poll); this is the CPU up to it. A script, not a test: nothing is asserted.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]

ESTIMATOR = """
import os, sys, time, types, importlib
from switchobs_ros import entry
def import_module(name):
    m = importlib.import_module(name)
    orig = m.EstimatorMixin._ready_log
    def ready(self):
        orig(self)
        print(f"READY {time.process_time():.4f}", file=sys.stderr, flush=True)
        os._exit(0)
    m.EstimatorMixin._ready_log = ready
    return m
entry.importlib = types.SimpleNamespace(import_module=import_module)
sys.argv = ["estimator", *sys.argv[1:]]
sys.exit(entry.estimator())
"""

BARE = """
import builtins, os, runpy, sys, time
_print = builtins.print
def p(*a, **k):
    _print(*a, **k)
    if a and "bare_republisher ready" in str(a[0]):
        _print(f"READY {time.process_time():.4f}", file=sys.stderr, flush=True)
        os._exit(0)
builtins.print = p
sys.argv = ["bench_node.py", "--republisher"]
runpy.run_path(os.environ["BENCH_NODE"], run_name="__main__")
"""


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--rounds", type=int, default=9)
    ap.add_argument("--before", help="another checkout, started the same way in the same rounds")
    ap.add_argument("--table32", default="", help="the 32-agent Kalman table this checkout reads (.npz; written "
                    "here from --table32-before in this checkout's container version if empty)")
    ap.add_argument("--table32-before", default="/tmp/boot/k32v4.npz", help="the table --before reads")
    a = ap.parse_args(argv)
    env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    env.update(ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST", OPENBLAS_NUM_THREADS="1", PYTHONSAFEPATH="1",
               BENCH_NODE=str(REPO / "bench" / "bench_node.py"))
    with tempfile.TemporaryDirectory(prefix="bench_ready_") as tmp:
        d = Path(tmp)
        (d / "agents32.yaml").write_text("agents: 32\nscenario: camera_agents\n")
        table = a.table32
        if not table:
            table = str(d / "k32.npz")
            subprocess.run([sys.executable, "-c", "import sys, switchobs_core as so; s = so.load_system(sys.argv[1]); "
                            "so.GainTable.load(sys.argv[2], system=s).save(sys.argv[3])", str(d / "agents32.yaml"),
                            a.table32_before, table], env=dict(env, PYTHONPATH=str(REPO)), check=True)
        h = "[" + ", ".join(["1.0"] * 32) + "]"
        args = ["--ros-args", "-p", f"system:={d / 'agents32.yaml'}", "-p", "schedule.mode:=periodic",
                "-p", f"schedule.h:={h}"]
        starts = {"this": (REPO, ESTIMATOR, [*args, "-p", f"gain_table:={table}"]),
                  "bare": (REPO, BARE, [])}
        if a.before:
            starts["before"] = (Path(a.before), ESTIMATOR, [*args, "-p", f"gain_table:={a.table32_before}"])
        cpu: dict[str, list[float]] = {k: [] for k in starts}
        names = list(starts)
        for r in range(a.rounds + 1):       # round 0: a warm-up (bytecode, page cache), not counted
            for name in names[r % len(names):] + names[:r % len(names)]:
                repo, code, extra = starts[name]
                e = dict(env, PYTHONPATH=str(repo), PYTHONPYCACHEPREFIX=str(d / f"pyc_{name}"))
                p = subprocess.run([sys.executable, "-c", code, *extra], env=e, capture_output=True, text=True,
                                   timeout=120)
                got = [x for x in p.stderr.splitlines() if x.startswith("READY ")]
                if not got:
                    print(f"{name}: no ready line\n{p.stderr[-2000:]}", file=sys.stderr)
                elif r:
                    cpu[name].append(float(got[0].split()[1]))
    print(f"CPU to ready (process, s), {a.rounds} rounds: median [min, max]; per-round ratio to the bare node")
    for name, v in cpu.items():
        if not v:
            continue
        ratio = statistics.median(x / b for x, b in zip(v, cpu["bare"]))
        print(f"- {name}: {statistics.median(v):.3f} [{min(v):.3f}, {max(v):.3f}]; / bare {ratio:.2f}x")
    if a.before and cpu["before"] and cpu["this"]:
        print(f"- this / before per round: {statistics.median(x / y for x, y in zip(cpu['this'], cpu['before'])):.2f}x")
    return 0


if __name__ == "__main__":
    sys.exit(main())
