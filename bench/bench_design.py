#!/usr/bin/env python
"""Performance benchmark of the offline gain design.

    python bench/bench_design.py            # full run (~3-6 min on the 2-core box)
    python bench/bench_design.py --quick    # ~1 min smoke version (fewer runs/points)

Prints a markdown report and writes it to ``bench/RESULTS-design.md`` (full run; the
``--quick`` run writes only when ``--out`` is given). A script, not a test: nothing is
asserted, the numbers are recorded with the machine, the date and the versions.

What is measured (all side by side in one run, medians of repeated runs):

1. ``switchobs design paper`` with the paper's four cycles as a subprocess, end to end
   including interpreter start (goal < 3 s), with a breakdown: bare interpreter, imports,
   cvxpy import, system + Designer, first SDP build (cvxpy compile + first solve per
   channel), the rest of the design, saving; and ``-X importtime`` per top-level package.
   The package need not be installed: the subprocess gets ``PYTHONPATH=<repo>``; if
   ``.venv/bin/switchobs`` exists it is timed as well.
2. The design-region map (tau = 1..5 x 99 values of s, both channels) with
   ``Designer.eta_min_map`` from a fresh Designer (goal < 5 s), against the NAIVE method:
   for each (tau, s, channel) the same bracket logic (scan of ETA_GRID, then brentq with
   the same xtol) where every evaluation of kappa(eta) is a fresh SDP solve
   (``LMISynthesizer.theta_star``, no KappaCurve, no cache). The naive synthesizers are
   built and compiled once per channel before timing, so the naive cost is solves only
   (the favourable case for the naive method). The naive map runs on a subsample and is
   extrapolated to the 495 points two ways: mean time per point x 495, and (better, since
   the cost per point depends on eta_min) the exact count of kappa evaluations the naive
   logic needs on the full map (counted with the closed-form kappa of DESIGN.md, no SDP)
   x the measured time per fresh solve. Accuracy: both against each other on the
   subsample and against the closed-form truth kappa(eta) = a + sqrt(1 + a^2),
   a = eta + d_i (DESIGN.md) on the whole map.
3. Scaling with the number of agents, ``scenarios.camera_agents(M)`` (n = 4(M + 1),
   N = M channels). M = 1 does not exist (one channel: no switched problem;
   camera_agents raises for M < 2), so M = 2..10. Per M: first build of a channel's SDP,
   time per SDP solve (theta_star at a fixed eta after the first solve) with Clarabel's
   own solve time, and a full design ``Designer(sys).design(Cycle([1.0] * M))`` from a
   fresh Designer. Every channel's observable subspace is camera + its agent (r_i = 8 for
   all M), so the per-channel SDP does not grow with n; as a supplement the SDP of the
   stacked pair (A, [C_1; ...; C_N]) of size n is timed to show how the solve itself
   scales with the matrix size. Growth exponents: least squares of log t against log n.
"""

from __future__ import annotations

import argparse
import datetime as _dt
import importlib.metadata as _md
import json
import math
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
if str(REPO) not in sys.path:
    sys.path.insert(0, str(REPO))

from _design_report import PAPER_CYCLES, report  # noqa: E402
from scipy.optimize import brentq  # noqa: E402

from switchobs_core.design.lmi import ETA_GRID, Designer  # noqa: E402
from switchobs_core.design.synthesis import LMISynthesizer  # noqa: E402
from switchobs_core.model.scenarios import camera_agents, paper_system  # noqa: E402
from switchobs_core.model.schedule import Cycle  # noqa: E402
from switchobs_core.sim.figures import S_VALUES, TAUS  # noqa: E402

PY = sys.executable
DELTA = 0.99
#: DESIGN.md's closed form of kappa for the paper model: a + sqrt(1 + a^2), a = eta + d_i.
PAPER_D = (0.2, 0.1)


# ----------------------------------------------------------------------------- helpers


def sub_env() -> dict:
    env = dict(os.environ)
    env["PYTHONPATH"] = str(REPO) + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
    return env


def run_timed(cmd, cwd, env) -> float:
    t = time.perf_counter()
    r = subprocess.run(cmd, cwd=cwd, env=env, capture_output=True, text=True)
    dt = time.perf_counter() - t
    if r.returncode != 0:
        raise RuntimeError(f"{cmd} failed ({r.returncode}):\n{r.stderr[-2000:]}")
    return dt


def machine_info() -> dict:
    cpu = "unknown"
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    try:
        nproc = subprocess.run(["nproc"], capture_output=True, text=True).stdout.strip()
    except OSError:
        nproc = str(os.cpu_count())

    def ver(p):
        try:
            return _md.version(p)
        except _md.PackageNotFoundError:
            return "not installed"

    try:
        head = subprocess.run(
            ["git", "-C", str(REPO), "rev-parse", "--short", "HEAD"], capture_output=True, text=True
        ).stdout.strip()
        dirty = subprocess.run(
            ["git", "-C", str(REPO), "status", "--porcelain", "--untracked-files=no"], capture_output=True, text=True
        ).stdout.strip()
        head += " (+ uncommitted changes)" if dirty else ""
    except OSError:
        head = "unknown"
    return {
        "date": _dt.datetime.now(_dt.UTC).strftime("%Y-%m-%d %H:%M UTC"),
        "nproc": nproc,
        "cpu": cpu,
        "python": platform.python_version(),
        "numpy": np.__version__,
        "scipy": ver("scipy"),
        "cvxpy": ver("cvxpy"),
        "clarabel": ver("clarabel"),
        "commit": head,
        "load": os.getloadavg(),
    }


# ------------------------------------------------------------------ 1. end to end CLI
BREAKDOWN = r"""
import json, sys, time
t0 = time.perf_counter()
import switchobs_core.cli as cli
from switchobs_core.cli import design  # noqa: F401
parser = cli.build_parser()          # imports every subcommand module, as `switchobs` does
t1 = time.perf_counter()
import cvxpy  # noqa: F401  (imported lazily by LMISynthesizer)
t2 = time.perf_counter()
from switchobs_core.model.scenarios import load_system
from switchobs_core.design.lmi import Designer
from switchobs_core.model.schedule import Cycle
system = load_system("paper")
des = Designer(system, delta=0.99)
t3 = time.perf_counter()
for ch in des.channels:              # first SDP of each channel: cvxpy compile + Clarabel solve
    ch.curve.raw(0.0)                # eta = 0 is the first point of every scan: no extra work
t4 = time.perf_counter()
cycles = [Cycle.from_ts(*map(float, c.split(","))) for c in sys.argv[2:]]
table = des.table(cycles, progress=False)
t5 = time.perf_counter()
table.save(sys.argv[1])
t6 = time.perf_counter()
print(json.dumps({"imports": t1 - t0, "cvxpy": t2 - t1, "system+Designer": t3 - t2,
                  "first SDP build": t4 - t3, "rest of design": t5 - t4, "save": t6 - t5,
                  "n_solves": sum(c.synth.n_solves for c in des.channels)}))
"""


def bench_e2e(runs: int, tmp: Path) -> dict:
    env = sub_env()
    out = str(tmp / "gains.json")
    cli_args = ["design", "paper"] + [a for c in PAPER_CYCLES for a in ("--cycle", c)] + ["-o", out]
    cmds = {"python -m switchobs_core.cli design ...": [PY, "-m", "switchobs_core.cli", *cli_args]}
    script = Path(PY).parent / "switchobs"
    if script.exists():
        cmds[".venv/bin/switchobs design ..."] = [str(script), *cli_args]
    base = {
        "python -c pass": [PY, "-c", "pass"],
        "python -c 'import switchobs_core.design.lmi'": [PY, "-c", "import switchobs_core.design.lmi"],
        "python -c 'import cvxpy'": [PY, "-c", "import cvxpy"],
        "python -c 'import switchobs_core.cli' + build_parser()": [
            PY,
            "-c",
            "import switchobs_core.cli as c; c.build_parser()",
        ],
    }
    times = {k: [] for k in [*cmds, *base]}
    bd_script = tmp / "breakdown.py"
    bd_script.write_text(BREAKDOWN)
    breakdown = []
    run_timed(cmds[next(iter(cmds))], tmp, env)  # warm the page cache once (not counted)
    for _ in range(runs):  # interleaved, so drift of the shared machine hits all alike
        for k, c in cmds.items():
            times[k].append(run_timed(c, tmp, env))
        for k, c in base.items():
            times[k].append(run_timed(c, tmp, env))
        r = subprocess.run(
            [PY, str(bd_script), str(tmp / "bd.json"), *PAPER_CYCLES], cwd=tmp, env=env, capture_output=True, text=True
        )
        if r.returncode != 0:
            raise RuntimeError(r.stderr)
        breakdown.append(json.loads(r.stdout.strip().splitlines()[-1]))
    # -X importtime of the real command (once): cumulative us per top-level import
    r = subprocess.run(
        [PY, "-X", "importtime", *cmds[next(iter(cmds))][1:]], cwd=tmp, env=env, capture_output=True, text=True
    )
    agg: dict[str, float] = {}
    for line in r.stderr.splitlines():
        if not line.startswith("import time:") or "|" not in line:
            continue
        parts = line.split("|")
        try:
            cum = int(parts[1])
        except ValueError:
            continue
        name = parts[2]
        if name.startswith(" ") and not name.startswith("  "):  # top level
            root = name.strip().split(".")[0]
            agg[root] = agg.get(root, 0.0) + cum * 1e-6
    top = sorted(agg.items(), key=lambda kv: -kv[1])[:8]
    chk = subprocess.run(
        [PY, "-c", "import sys, cvxpy; print(all(m in sys.modules for m in ('scipy.interpolate', 'scipy.optimize')))"],
        cwd=tmp,
        env=env,
        capture_output=True,
        text=True,
    ).stdout.strip()
    env0 = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    installed = (
        subprocess.run([PY, "-c", "import switchobs_core"], cwd=tmp, env=env0, capture_output=True).returncode == 0
    )
    return {
        "times": times,
        "cmds": cmds,
        "breakdown": breakdown,
        "importtime": top,
        "cvxpy_imports_scipy": chk,
        "installed": installed,
    }


# ------------------------------------------------------------------ 2. the design map
def kappa_closed(eta: float, ch: int) -> float:
    a = eta + PAPER_D[ch]
    return a + math.sqrt(1 + a * a)


def scan_brent(kap, mu, active, inactive, delta, xtol):
    """The bracket logic of ChannelDesigner.eta_min_interp with kappa = kap (no cache)."""

    def g(e):
        return e * active - mu * inactive - math.log(kap(e) / delta)

    prev = None
    for eta in ETA_GRID:
        if g(eta) >= 0:
            break
        prev = eta
    else:
        return float("nan")
    if prev is None:
        return 0.0
    return float(brentq(g, prev, eta, xtol=xtol))


def naive_point(synths, mus, tau, s, delta, counter):
    c = Cycle.from_ts(tau, s)
    out = []
    for i in range(2):
        syn = synths[i]

        def kap(e, syn=syn):
            counter[0] += 1
            return math.sqrt(max(syn.theta_star(e), 1.0))  # a fresh SDP solve every time

        out.append(scan_brent(kap, mus[i], c.h[i], c.inactive(i + 1), delta, 1e-7))
    return out


def truth_point(mus, tau, s, delta, counter=None):
    c = Cycle.from_ts(tau, s)
    out = []
    for i in range(2):

        def kap(e, i=i):
            if counter is not None:
                counter[0] += 1
            return kappa_closed(e, i)

        out.append(scan_brent(kap, mus[i], c.h[i], c.inactive(i + 1), delta, 1e-7 if counter else 1e-13))
    return out


def bench_map(reps: int, naive_reps: int, sub_taus, sub_s) -> dict:
    system = paper_system()
    ours_t, ours_build, ours_solves, maps = [], [], [], []
    # naive synthesizers: built and compiled once (favourable to the naive method)
    d0 = Designer(system, delta=DELTA)
    mus = [ch.mu for ch in d0.channels]
    synths = [LMISynthesizer(ch.decomp.A_o, ch.decomp.C_o) for ch in d0.channels]
    for syn in synths:
        syn.theta_star(1.0)
    sub = [(t, s) for t in sub_taus for s in sub_s]
    naive_t, naive_solves, naive_vals = [], [], None
    for k in range(max(reps, naive_reps)):  # interleaved: ours, then naive, each rep
        if k < reps:
            t = time.perf_counter()
            d = Designer(system, delta=DELTA)
            t1 = time.perf_counter()
            m = d.eta_min_map(TAUS, S_VALUES, progress=False)
            t2 = time.perf_counter()
            ours_build.append(t1 - t)
            ours_t.append(t2 - t1)
            ours_solves.append(sum(ch.synth.n_solves for ch in d.channels))
            maps.append(m)
        if k < naive_reps:
            cnt = [0]
            n0 = sum(s.n_solves for s in synths)
            t = time.perf_counter()
            vals = [naive_point(synths, mus, tau, s, DELTA, cnt) for tau, s in sub]
            naive_t.append(time.perf_counter() - t)
            naive_solves.append(sum(s.n_solves for s in synths) - n0)
            naive_vals = np.array(vals)
    warm = []
    for _ in range(3):  # same Designer again: every kappa is cached, 0 SDP solves
        n0 = sum(ch.synth.n_solves for ch in d.channels)
        t = time.perf_counter()
        d.eta_min_map(TAUS, S_VALUES, progress=False)
        warm.append(time.perf_counter() - t)
        assert sum(ch.synth.n_solves for ch in d.channels) == n0
    ours = maps[-1]
    same = all(np.array_equal(m, ours, equal_nan=True) for m in maps)
    # truth map (closed-form kappa) and the naive evaluation count on the full map
    truth = np.array([[truth_point(mus, tau, s, DELTA) for s in S_VALUES] for tau in TAUS])
    cnt = [0]
    for tau in TAUS:
        for s in S_VALUES:
            truth_point(mus, tau, s, DELTA, cnt)
    full_evals = cnt[0]
    cnt_sub = [0]
    for tau, s in sub:
        truth_point(mus, tau, s, DELTA, cnt_sub)
    # where the subsample sits in the full arrays
    ti = [TAUS.index(float(t)) for t in sub_taus]
    si = [int(np.argmin(np.abs(np.asarray(S_VALUES) - s))) for s in sub_s]
    ours_sub = np.array([ours[a, b] for a in ti for b in si])
    truth_sub = np.array([truth[a, b] for a in ti for b in si])
    # the SDP vs the closed form on the cached grid (is the truth a truth?)
    oracle_rel = 0.0
    for i, ch in enumerate(d.channels):
        for e, kv in ch.curve.cache.items():
            oracle_rel = max(oracle_rel, abs(kv / kappa_closed(e, i) - 1))
    rel = np.abs(ours - truth) / np.maximum(np.abs(truth), 1e-12)
    return {
        "ours_t": ours_t,
        "ours_build": ours_build,
        "ours_solves": ours_solves,
        "ours_deterministic": same,
        "warm": warm,
        "nan": int(np.isnan(ours).sum()),
        "naive_t": naive_t,
        "naive_solves": naive_solves,
        "n_sub": len(sub),
        "sub_taus": sub_taus,
        "sub_s": sub_s,
        "full_evals": full_evals,
        "sub_evals": cnt_sub[0],
        "diff_ours_naive": float(np.nanmax(np.abs(ours_sub - naive_vals))),
        "rel_ours_naive": float(np.nanmax(np.abs(ours_sub - naive_vals) / np.maximum(naive_vals, 1e-12))),
        "diff_naive_truth": float(np.nanmax(np.abs(naive_vals - truth_sub))),
        "diff_ours_truth": float(np.nanmax(np.abs(ours - truth))),
        "rel_ours_truth": float(np.nanmax(rel)),
        "worst_ours_truth": tuple(int(x) for x in np.unravel_index(np.nanargmax(rel), rel.shape)),
        "oracle_rel": oracle_rel,
        "eta_range": (float(np.nanmin(ours)), float(np.nanmax(ours))),
        "ours": ours,
        "truth": truth,
    }


# ------------------------------------------------------------------ 3. scaling in M
def bench_scaling(Ms, reps: int, solves_per_rep: int, eta: float, central_max_M: int, central_reps: int) -> list[dict]:
    """Interleaved: rep outer, M inner, so a burst of load on the shared box hits every M alike."""
    systems = {M: camera_agents(M) for M in Ms}
    acc = {
        M: {k: [] for k in ("build", "solve", "solver", "design", "design_solves", "central_build", "central_solve")}
        for M in Ms
    }
    info: dict[int, dict] = {}
    for rep in range(reps):
        for M in Ms:
            system, a = systems[M], acc[M]
            ch0 = system.decompositions[0]
            # first build: construct + first solve (cvxpy compile + Clarabel) of a NEW problem
            t = time.perf_counter()
            syn = LMISynthesizer(ch0.A_o, ch0.C_o)
            syn.theta_star(eta)
            a["build"].append(time.perf_counter() - t)
            for _ in range(solves_per_rep):  # later solves of the same compiled problem
                t = time.perf_counter()
                syn.theta_star(eta)
                a["solve"].append(time.perf_counter() - t)
                a["solver"].append(syn._stage1.solver_stats.solve_time or float("nan"))
            # full design from a fresh Designer (the decompositions belong to the system: reused)
            t = time.perf_counter()
            d = Designer(system, delta=DELTA)
            des = d.design(Cycle([1.0] * M))
            a["design"].append(time.perf_counter() - t)
            a["design_solves"].append(sum(ch.synth.n_solves for ch in d.channels))
            info[M] = {"eta_min": (min(des.eta_min), max(des.eta_min)), "certified": des.certified, "f_max": max(des.f)}
            # supplement: the SDP of the stacked pair (A, [C_1; ...; C_N]), matrix size n
            if M <= central_max_M and rep < central_reps:
                t = time.perf_counter()
                csyn = LMISynthesizer(system.A, system.C_stacked)
                csyn.theta_star(eta)
                a["central_build"].append(time.perf_counter() - t)
                for _ in range(2):
                    t = time.perf_counter()
                    csyn.theta_star(eta)
                    a["central_solve"].append(time.perf_counter() - t)
        print(f"  scaling rep {rep + 1}/{reps} done (load {os.getloadavg()[0]:.2f})", file=sys.stderr, flush=True)
    rows = []
    for M in Ms:
        system = systems[M]
        rows.append(
            {
                "M": M,
                "n": system.n,
                "N": system.N,
                "r": sorted({d.r for d in system.decompositions}),
                "mu": sorted(round(d.mu, 4) for d in system.decompositions),
                **acc[M],
                **info[M],
            }
        )
    return rows


# ----------------------------------------------------------------------------- report


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="~1 minute version (fewer runs and points)")
    ap.add_argument(
        "--out",
        type=Path,
        default=None,
        help="markdown file to write (default: bench/RESULTS-design.md for a full run, nothing for --quick)",
    )
    ap.add_argument("--eta", type=float, default=1.0, help="eta of the timed SDP solves (scaling)")
    args = ap.parse_args()
    q = args.quick
    t_start = time.perf_counter()
    info = machine_info()
    with tempfile.TemporaryDirectory(prefix="bench_design_") as tmpd:
        tmp = Path(tmpd)
        print("[1/3] end-to-end CLI ...", file=sys.stderr, flush=True)
        info["load_sections"] = [os.getloadavg()[0]]
        e2e = bench_e2e(3 if q else 7, tmp)
    print("[2/3] design-region map, ours vs naive ...", file=sys.stderr, flush=True)
    info["load_sections"].append(os.getloadavg()[0])
    if q:
        mp = bench_map(2, 1, (2.0,), (0.1, 0.3, 0.5, 0.7, 0.9))
    else:
        mp = bench_map(5, 3, (2.0, 3.0), tuple(round(0.1 * k, 1) for k in range(1, 10)))
    print("[3/3] scaling in M ...", file=sys.stderr, flush=True)
    info["load_sections"].append(os.getloadavg()[0])
    if q:
        sc = bench_scaling([2, 4, 7, 10], 2, 3, args.eta, central_max_M=7, central_reps=1)
    else:
        sc = bench_scaling(list(range(2, 11)), 5, 3, args.eta, central_max_M=10, central_reps=2)
    info["load_end"] = os.getloadavg()
    text = report(info, e2e, mp, sc, args, time.perf_counter() - t_start)
    print(text)
    out = args.out if args.out is not None else (None if q else REPO / "bench" / "RESULTS-design.md")
    if out is not None:
        tmpf = out.with_name(out.name + ".tmp")
        tmpf.write_text(text)
        os.replace(tmpf, out)
        print(f"wrote {out}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
