#!/usr/bin/env python
"""Scaling benchmark of the offline side (issue 21): one camera and M agents, M = 2 ... 32.

    python bench/bench_scale.py                 # M = 2, 4, 8, 16, 32, both families, plans
    python bench/bench_scale.py --agents 2 4    # a subset
    python bench/bench_scale.py --out FILE      # also write the markdown section to FILE

What is measured (``camera_agents`` with M agents, n = 4 (M + 1), every h_i = 1 s; one run each,
as subprocesses, so that every number includes nothing of the others):

1. ``switchobs design <system> --cycle-h 1,...,1`` (LMI family, table ``.json``) and
   ``... --gains kalman --rate 50`` (table ``.npz``): wall time, CPU time (user + system of the
   child) and peak memory (the child's ``ru_maxrss``), and the table file's size;
2. loading each table in a fresh interpreter: ``GainTable.load(path, system=...)`` and, for the
   Kalman table, building its design (``table.kalman_design``), timed after the imports (wall and
   CPU of that call only);
3. ``switchobs plan <system> --rate 100 --json`` for the paper's model and M = 4 (CLI defaults:
   h_min 0.5 s, tau_max 4 s, every cyclic order for N <= 4, the LMI and Kalman reports of the
   planned cycle): wall and CPU of the whole command, and of the search alone
   (``plan_schedule``, timed after the imports in a fresh interpreter).

The machine is shared: the load average before and after is printed with the results, and CPU
time is the number that does not depend on the other users. A script, not a test: nothing is
asserted. Goals (issue 21): Kalman design at M = 32 under 60 s wall and 2 GiB; LMI design at M = 32
under 30 s; every table loads in under 1 s; plan under 3 s (paper) and 10 s (M = 4).
"""

from __future__ import annotations

import argparse
import datetime as _dt
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from bench_design import machine_info  # the one machine description of the benchmarks

REPO = Path(__file__).resolve().parents[1]
PY = sys.executable
ENV = dict(os.environ, PYTHONPATH=str(REPO), OPENBLAS_NUM_THREADS="1")

LOAD_SNIPPET = """
import sys, time
from switchobs_core.threads import single_threaded_blas
single_threaded_blas()
from switchobs_core.gains import GainTable
from switchobs_core.scenarios import load_system
from switchobs_core.schedule import Cycle
system = load_system(sys.argv[2])
t, c = time.perf_counter(), time.process_time()
table = GainTable.load(sys.argv[1], system=system)
if table.family == "kalman":
    table.kalman_design([Cycle([1.0] * system.N)], system)
print(time.perf_counter() - t, time.process_time() - c)
"""


PLAN_SNIPPET = """
import sys, time
from switchobs_core.threads import single_threaded_blas
single_threaded_blas()
from switchobs_core.plan import plan_schedule
from switchobs_core.scenarios import load_system
system = load_system(sys.argv[1])
t, c = time.perf_counter(), time.process_time()
res = plan_schedule(system, 100.0, progress=False)
print(time.perf_counter() - t, time.process_time() - c, res.evaluations)
"""


def _run(cmd: list[str]) -> dict:
    """Run ``cmd``; its wall time, CPU time and peak RSS (``os.wait4``: this child only), stdout and
    return code."""
    with tempfile.TemporaryFile("w+") as out, tempfile.TemporaryFile("w+") as err:
        t = time.perf_counter()
        p = subprocess.Popen(cmd, env=ENV, stdout=out, stderr=err, text=True, cwd=REPO)
        _, status, ru = os.wait4(p.pid, 0)
        wall = time.perf_counter() - t
        p.returncode = os.waitstatus_to_exitcode(status)
        out.seek(0)
        err.seek(0)
        text, etext = out.read(), err.read()
    return {"wall": wall, "cpu": ru.ru_utime + ru.ru_stime, "rss_mib": ru.ru_maxrss / 1024, "rc": p.returncode,
            "out": text, "err": etext.strip().splitlines()[-1:] if p.returncode else []}


def _system_file(tmp: Path, M: int) -> Path:
    path = tmp / f"camera_{M}.yaml"
    path.write_text(f"scenario: camera_agents\nagents: {M}\n")
    return path


def _switchobs(*args: str) -> list[str]:
    return [PY, "-m", "switchobs_core.cli", *args]


def bench_design(tmp: Path, M: int, family: str) -> dict:
    """Design and load of one table (items 1 and 2 of the module docstring)."""
    sysf = _system_file(tmp, M)
    out = tmp / f"m{M}_{family}.{'npz' if family == 'kalman' else 'json'}"
    extra = ["--gains", "kalman", "--rate", "50"] if family == "kalman" else []
    r = _run(_switchobs("design", str(sysf), "--cycle-h", ",".join(["1"] * M), *extra, "-o", str(out)))
    r["size_mib"] = out.stat().st_size / 2**20 if out.exists() else float("nan")
    if r["rc"] == 0:
        ld = _run([PY, "-c", LOAD_SNIPPET, str(out), str(sysf)])
        if ld["rc"] == 0:
            r["load_wall"], r["load_cpu"] = (float(v) for v in ld["out"].split())
    return r


def bench_plan(tmp: Path, which: str) -> dict:
    """``switchobs plan`` end to end (item 3)."""
    target = "paper" if which == "paper" else str(_system_file(tmp, int(which)))
    r = _run(_switchobs("plan", target, "--rate", "100", "--json"))
    s = _run([PY, "-c", PLAN_SNIPPET, target])
    if s["rc"] == 0:
        r["search_wall"], r["search_cpu"], r["evaluations"] = (float(v) for v in s["out"].split())
    return r


def _machine() -> str:
    info = machine_info()          # bench_design's: the CPU, cores and versions of this machine
    return f"{platform.node()}: {info['cpu']}, {os.cpu_count()} cores, Python {platform.python_version()}"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--agents", type=int, nargs="+", default=[2, 4, 8, 16, 32])
    ap.add_argument("--families", nargs="+", default=["lmi", "kalman"], choices=["lmi", "kalman"])
    ap.add_argument("--no-plan", action="store_true")
    ap.add_argument("--no-design", action="store_true", help="only the plans")
    ap.add_argument("--out", type=Path)
    a = ap.parse_args(argv)
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True,
                            cwd=REPO).stdout.strip()
    load0 = os.getloadavg()
    rows = []
    with tempfile.TemporaryDirectory(prefix="bench_scale_") as td:
        tmp = Path(td)
        for M in [] if a.no_design else sorted(a.agents):
            for fam in a.families:
                r = bench_design(tmp, M, fam)
                rows.append((M, fam, r))
                print(f"M={M} {fam}: {r['wall']:.1f} s wall, {r['cpu']:.1f} s CPU, rc {r['rc']} {r['err']}",
                      file=sys.stderr, flush=True)
        plans = [] if a.no_plan else [(w, bench_plan(tmp, w)) for w in ("paper", "4")]
    load1 = os.getloadavg()
    lines = [
        f"### Scaling with the number of agents (issue 21), {_dt.date.today().isoformat()}",
        "",
        f"Machine: {_machine()}; commit {commit}; load average {load0[0]:.1f} before, {load1[0]:.1f} after "
        "(a shared machine: wall times carry the other users' load, CPU times do not).",
        "Command: `python bench/bench_scale.py` (`camera_agents`, every h_i = 1 s; Kalman: `--gains kalman "
        "--rate 50`, table `.npz`; LMI: table `.json`; one subprocess each, `OPENBLAS_NUM_THREADS=1`).",
        "",
        "| M (n) | family | design wall | design CPU | peak RSS | table | load wall | load CPU |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for M, fam, r in rows:
        if r["rc"]:
            lines.append(f"| {M} ({4 * (M + 1)}) | {fam} | failed: {' '.join(r['err'])} | | | | | |")
            continue
        lw = f"{r['load_wall']:.2f} s" if "load_wall" in r else "-"
        lc = f"{r['load_cpu']:.2f} s" if "load_cpu" in r else "-"
        lines.append(f"| {M} ({4 * (M + 1)}) | {fam} | {r['wall']:.1f} s | {r['cpu']:.1f} s | "
                     f"{r['rss_mib']:.0f} MiB | {r['size_mib']:.2f} MiB | {lw} | {lc} |")
    if plans:
        lines += ["", "| `switchobs plan ... --rate 100` | search (`plan_schedule`) wall | search CPU | cost "
                  "evaluations | end to end wall | end to end CPU | exit |", "|---|---|---|---|---|---|---|"]
        nan = float("nan")
        for w, r in plans:
            lines.append(f"| {'paper' if w == 'paper' else f'camera_agents M = {w}'} | "
                         f"{r.get('search_wall', nan):.2f} s | {r.get('search_cpu', nan):.2f} s | "
                         f"{r.get('evaluations', nan):.0f} | {r['wall']:.1f} s | {r['cpu']:.1f} s | {r['rc']} |")
    text = "\n".join(lines) + "\n"
    print(text)
    if a.out:
        a.out.write_text(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
