"""The Kalman table's rows verified ahead (``table/rows.py``) against verified by the caller, at 32
agents (n = 132) with the ticks at 50 Hz: the CPU per row of each thread.

    OPENBLAS_NUM_THREADS=1 python bench/bench_rows_ahead.py [--table /tmp/boot/k32v4.npz] [--seconds 10] [--rounds 2]

Each round runs ``bench_pipeline.py``'s ``pipeline`` child of this checkout twice (with the worker, and
with ``AHEAD = 0``: every row read and verified by the caller), on the first ``--seconds`` of
camera_sim's stream (every tick the first visit of its phase), paced (``--pace sleep``; ``--evict MB``
written between ticks), and counts the own CPU (``time.thread_time``) of the caller's reads
(``LazyRows._read``), the worker's (``LazyRows._read_into``) and the caller's hand-overs
(``_Ahead.take``), per row and per answer.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from collections import Counter
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
FNS = (("LazyRows", "_read", "read"), ("LazyRows", "_read_into", "read ahead"), ("_Ahead", "take", "take"))


def child(argv: list[str], ahead: bool) -> None:
    """The pipeline child with the three functions counted; prints one JSON line after its own."""
    sys.path.insert(0, str(REPO))
    sys.path.insert(0, str(REPO / "bench"))
    from switchobs_core.table import rows as R
    got: Counter = Counter()

    def counted(fn, label):
        def w(*a, **k):
            who = "caller" if threading.current_thread() is threading.main_thread() else "worker"
            c0 = time.thread_time()
            r = fn(*a, **k)
            got[f"{who} {label} us"] += time.thread_time() - c0
            got[f"{who} {label} n"] += 1
            return r
        return w

    for cls, name, label in FNS:
        owner = getattr(R, cls)
        setattr(owner, name, counted(getattr(owner, name), label))
    if not ahead:
        R.AHEAD = 0
    import contextlib
    import io

    import bench_pipeline as bp
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        bp.main(argv)
    answers = json.loads(out.getvalue().strip().splitlines()[-1])["answers"]
    print(json.dumps({"answers": answers, **{k: v * 1e6 if k.endswith("us") else v for k, v in got.items()}}))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--table", default="/tmp/boot/k32v4.npz")
    ap.add_argument("--seconds", type=float, default=10.0)
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--evict", type=float, default=0.0, help="MiB written between ticks (bench_pipeline.py --evict)")
    ap.add_argument("--rows-child", choices=("ahead", "caller"), default=None, help=argparse.SUPPRESS)
    a, rest = ap.parse_known_args()
    if a.rows_child:
        child(rest, a.rows_child == "ahead")
        return 0
    sys.path.insert(0, str(REPO / "bench"))
    sys.path.insert(0, str(REPO))
    import bench_pipeline as bp

    from switchobs_core.table.rows import AHEAD
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1", PYTHONPATH=str(REPO))
    res: dict[str, list[dict]] = {"ahead": [], "caller": []}
    with tempfile.TemporaryDirectory(prefix="bench_rows_ahead_") as tmp:
        stream = Path(tmp) / "stream.npz"
        bp.make_stream(32, 50.0, a.seconds + 1, stream)
        args = ["--child", str(REPO), "--stream", str(stream), "--what", "pipeline", "--agents", "32", "--table",
                a.table, "--first", str(a.seconds), "--steady", str(a.seconds), "--steady-len", "1", "--pace", "sleep",
                *(["--evict", str(a.evict)] if a.evict else [])]
        for r in range(a.rounds):
            for mode in (("ahead", "caller") if r % 2 == 0 else ("caller", "ahead")):
                p = subprocess.run([sys.executable, __file__, "--rows-child", mode, *args], env=env,
                                   capture_output=True, text=True)
                if p.returncode:
                    sys.exit(p.stderr[-3000:])
                res[mode].append(json.loads(p.stdout.strip().splitlines()[-1]))
    evict = f" --evict {a.evict:g}" if a.evict else ""
    print(f"Command: `OPENBLAS_NUM_THREADS=1 python bench/bench_rows_ahead.py --table {a.table} --seconds "
          f"{a.seconds:g} --rounds {a.rounds}{evict}` (load {os.getloadavg()[0]:.1f} after)\n")
    print("| rows verified | caller: reads (us/row, rows) | caller: hand-overs (us/row) | worker: reads (us/row, rows) "
          "| all threads, us per answer |")
    print("|---|---|---|---|---|")
    for mode, label in (("caller", "by the caller (`AHEAD = 0`)"), ("ahead", f"ahead (`AHEAD = {AHEAD}`)")):
        def med(key, per="n", rs=res[mode]):
            vals = [r.get(f"{key} us", 0.0) / max(r.get(f"{key} {per}", 0), 1) if per == "n" else
                    r.get(f"{key} us", 0.0) / r["answers"] for r in rs]
            return statistics.median(vals)

        def rows(key, rs=res[mode]):
            return statistics.median([r.get(f"{key} n", 0) for r in rs])
        total = statistics.median([sum(v for k, v in r.items() if k.endswith(" us")) / r["answers"]
                                   for r in res[mode]])
        print(f"| {label} | {med('caller read'):.1f} ({rows('caller read'):.0f}) | {med('caller take'):.1f} | "
              f"{med('worker read ahead'):.1f} ({rows('worker read ahead'):.0f}) | {total:.1f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
