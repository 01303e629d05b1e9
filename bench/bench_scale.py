#!/usr/bin/env python
"""Scaling benchmark of the offline side: one camera and M agents, M = 2 ... 32.

    python bench/bench_scale.py                 # M = 2, 4, 8, 16, 32, both families, plans
    python bench/bench_scale.py --agents 2 4    # a subset
    python bench/bench_scale.py --out FILE      # also write the markdown section to FILE
    python bench/bench_scale.py --cost          # only the online cost per sample
    python bench/bench_scale.py --cost --steady --before /tmp/base9   # the node pattern beside another tree

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

4. ``--cost``: the online cost per sample, in this process, of ``camera_agents`` with
   M = 2, 8, 16, 32 (n = 12, 36, 68, 132), periodic cycle (every h_i = 1 s), 50 Hz, noisy samples
   (1 mm) of the noise-free plant (the design's memory budget is lifted for M = 32:
   :func:`_lift_design_budget`). Estimators, interleaved in blocks of ``--block`` samples (the
   order rotated from block to block) and timed by CPU time per block; the medians over the
   blocks after the first two are reported: the ``kalman`` table with the exact bound (the
   default), with ``rounding_bound=False``, with ``envelope()`` after every update (what the node
   does: the bound read amortised from n = 32 on, :mod:`switchobs_core.bounds.read`) and with
   ``envelope(amortised=False)`` (an eigenvalue problem at every read, the reading before);
   ``kalman-online`` (exact bound on); a reference Kalman filter in standard form written
   here (:class:`ReferenceKF`: numpy, discretisation cached, Joseph update); filterpy's
   ``KalmanFilter`` if it is installed (it is not a dependency); and the bare floor
   ``x = F x + K (y - H x)`` with precomputed gains. Then the growth exponent of each (least
   squares of log cost on log n) and the cost goals at n = 132 as ratios. The table's first
   ``len(startup) + K`` samples visit each of its phases for the first time (671 at n = 12, 2351
   at n = 36, 3525 at n = 132: a map's norms are taken at its first visit); ``--steady`` runs
   every estimator over them untimed first, so that the timed samples revisit phases. The node
   pattern is timed with ``bound='phase'`` too (:mod:`switchobs_core.runtime.bound_option`), and its
   exact bound (and, in a second untimed pass with ``noise_max`` 1 mm, its noise bound) is compared
   with the ellipsoid's on the same samples. With ``--before TREE`` (:mod:`_scale_before`): the node
   pattern, the table without a bound and the reference of this checkout and of ``TREE``, one child
   process per (tree, M) with ``PYTHONPATH`` at its tree, the trees alternating over ``--rounds``, one
   table per M shared; the node pattern over the reference per child, and the trees' exact bounds
   on the same samples.

The machine is shared: the load average before and after is printed with the results, and CPU
time is the number that does not depend on the other users. A script, not a test: nothing is
asserted. Goals: Kalman design at M = 32 under 60 s wall and 2 GiB; LMI design at M = 32
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

import numpy as np

REPO = Path(__file__).resolve().parents[1]
if "--child" in sys.argv:   # a --before child: its tree's package ahead of this checkout's (bench_design adds REPO)
    sys.path[:0] = [sys.argv[sys.argv.index("--child") + 1], str(REPO)]
from bench_design import machine_info  # noqa: E402  (the one machine description of the benchmarks)

PY = sys.executable
ENV = dict(os.environ, PYTHONPATH=str(REPO), OPENBLAS_NUM_THREADS="1")

LOAD_SNIPPET = """
import sys, time
from switchobs_core.threads import single_threaded_blas
single_threaded_blas()
from switchobs_core.table.gains import GainTable
from switchobs_core.model.scenarios import load_system
from switchobs_core.model.schedule import Cycle
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
from switchobs_core.design.plan import plan_schedule
from switchobs_core.model.scenarios import load_system
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


class ReferenceKF:
    """A Kalman filter in standard form, written here (independent of switchobs_core): ``F = e^{A dt}``
    and ``Q_d`` (van Loan) cached per step; predict ``x = F x``, ``P = F P F' + Q_d``; correct
    ``S = H P H' + R``, ``K = P H' S^-1``, ``x += K (y - H x)``, ``P = (I - K H) P (I - K H)' + K R K'``
    (Joseph), symmetrised."""

    def __init__(self, A: np.ndarray, Q_c: np.ndarray, P0: np.ndarray, R: np.ndarray):
        self.A, self.Q_c, self.R = A, Q_c, R
        self.n = A.shape[0]
        self.x, self.P, self.I = np.zeros(self.n), P0.copy(), np.eye(self.n)
        self.t: float | None = None
        self.K: np.ndarray | None = None
        self._disc: dict = {}

    def _discretize(self, dt: float) -> tuple[np.ndarray, np.ndarray]:
        from scipy.linalg import expm

        if round(dt * 1e9) not in self._disc:
            # van Loan: expm([[A, Q_c], [0, -A']] dt) = [[F, G], [0, F^-T]] and Q_d = G F'
            n = self.n
            V = expm(np.block([[self.A, self.Q_c], [np.zeros((n, n)), -self.A.T]]) * dt)
            self._disc[round(dt * 1e9)] = (V[:n, :n], V[:n, n:] @ V[:n, :n].T)
        return self._disc[round(dt * 1e9)]

    def update(self, t: float, H: np.ndarray, y: np.ndarray) -> np.ndarray:
        if self.t is not None and t > self.t:
            F, Qd = self._discretize(t - self.t)
            self.x = F @ self.x
            self.P = F @ self.P @ F.T + Qd
        self.t = t
        PHt = self.P @ H.T
        self.K = K = PHt @ np.linalg.inv(H @ PHt + self.R)
        self.x = self.x + K @ (y - H @ self.x)
        IKH = self.I - K @ H
        P = IKH @ self.P @ IKH.T + K @ self.R @ K.T
        self.P = 0.5 * (P + P.T)
        return self.x


def _lift_design_budget(budget: int = 4 << 30) -> None:
    """Let the Kalman design take up to ``budget`` bytes: at M = 32, h_i = 1 s, 50 Hz it estimates
    1.05 GiB and ``switchobs_core.ranges``' default budget (1 GiB) refuses it (measured: a
    973 MiB peak for the same design)."""
    import functools

    from switchobs_core import ranges
    from switchobs_core.design import kalman

    if getattr(kalman, "check_size", None) is ranges.check_size:
        kalman.check_size = functools.partial(ranges.check_size, budget=budget)


def _cost_setup(M: int, samples: int, h: float, rate: float = 50.0, cache: Path | None = None) -> tuple:
    """(system, cycle, Kalman table, stream of (t, channel, H, y)) for ``camera_agents(M)``, every
    channel active ``h`` seconds; ``cache``: a directory where the table is saved at its design and
    loaded from afterwards (the trees of ``--before`` share one design)."""
    import switchobs_core as so

    system = so.camera_agents(M)
    cycle = so.Cycle([h] * M)
    path = None if cache is None else cache / f"kalman_{M}_{h:g}_{rate:g}.npz"
    if path is not None and path.exists():
        table = so.GainTable.load(path, system=system)
    else:
        _lift_design_budget()
        table = so.kalman_table(system, [so.design_kalman(system, cycle, rate)])
        if path is not None:
            table.save(path)
    sched = so.PeriodicSchedule(cycle)
    rng = np.random.default_rng(M)
    x = np.zeros(system.n)
    x[0::4], x[1::4] = rng.uniform(-5, 5, M + 1), rng.uniform(-5, 5, M + 1)     # positions; at rest
    stream = []
    for k in range(samples):
        t = k / rate
        ch = sched.channel_at(t)
        H = np.asarray(system.C[ch - 1])
        stream.append((t, ch, H, H @ x + rng.normal(scale=1e-3, size=H.shape[0])))
    return system, cycle, table, stream


def _estimators(system, cycle, table, stream) -> tuple[dict, list]:
    """(name -> per-sample callable ``f(k)`` on sample ``k`` of ``stream`` (module docstring, item 4),
    the three table observers)."""
    import switchobs_core as so

    noise = so.default_noise(system)
    A = np.asarray(system.A, dtype=float)

    def observer(**kw):
        return so.SwitchedObserver(system, table, "periodic", [cycle], **kw)

    tab, nob, env, onl = observer(), observer(rounding_bound=False), observer(), observer(family="kalman-online")
    amo = observer()
    c0 = time.process_time()
    pha = observer(bound="phase")       # the bound's constants proved here (untimed)
    pha.constants_cpu = time.process_time() - c0
    bounds: dict = {"node": {}, "phase": {}, "on": {}}

    def node(k):
        env.update(stream[k][0], stream[k][1], stream[k][3])
        bounds["node"][k] = env.envelope().exact_bound

    def phase(k):
        pha.update(stream[k][0], stream[k][1], stream[k][3])
        bounds["phase"][k] = pha.envelope().exact_bound
        bounds["on"][k] = pha.rounding.phase.j >= 0

    ref = ReferenceKF(A, noise.Q_c, noise.P0, noise.R(1))
    # the floor's gains: the reference recursion's, run once over the stream beforehand
    pre = ReferenceKF(A, noise.Q_c, noise.P0, noise.R(1))
    F = pre._discretize(stream[1][0] - stream[0][0])[0]
    gains = []
    for t, _, H, y in stream:
        pre.update(t, H, y)
        gains.append(pre.K)
    xf = [np.zeros(system.n)]

    def floor(k):
        t, ch, H, y = stream[k]
        x = F @ xf[0]
        x += gains[k] @ (y - H @ x)
        xf[0] = x

    out = {
        "kalman table, exact bound": lambda k: tab.update(stream[k][0], stream[k][1], stream[k][3]),
        "kalman table, rounding_bound=False": lambda k: nob.update(stream[k][0], stream[k][1], stream[k][3]),
        "kalman table + envelope() (the node)": node,
        "kalman table + envelope(), bound='phase'": phase,
        "kalman table + envelope(amortised=False)": lambda k: (amo.update(stream[k][0], stream[k][1], stream[k][3]),
                                                               amo.envelope(amortised=False)),
        "kalman-online, exact bound": lambda k: onl.update(stream[k][0], stream[k][1], stream[k][3]),
        "reference Kalman filter (standard form, numpy)": lambda k: ref.update(stream[k][0], stream[k][2],
                                                                               stream[k][3]),
    }
    try:
        from filterpy.kalman import KalmanFilter
    except ImportError:
        pass
    else:
        kf = KalmanFilter(dim_x=system.n, dim_z=4)
        kf.F, kf.Q, kf.P, kf.R = F, ref._discretize(1 / 50.0)[1], noise.P0.copy(), noise.R(1)

        def fpy(k):
            kf.predict()
            kf.update(stream[k][3], H=stream[k][2])

        out["filterpy KalmanFilter"] = fpy
    out["bare floor x = F x + K (y - H x)"] = floor
    pha.bounds = bounds
    return out, [tab, nob, env, amo, pha]


def _steady_from(system, cycle, table) -> int:
    """The first sample at which every phase of the Kalman table was visited once: its start-up
    phases and one period (50 Hz from t = 0)."""
    import switchobs_core as so

    kd = so.SwitchedObserver(system, table, "periodic", [cycle], rounding_bound=False)._gains.kalman
    return len(kd.startup) + kd.pattern.K


def noise_tightness(system, cycle, table, stream, warm: int, noise_max: float = 1e-3) -> tuple[float, float]:
    """The noise bound (a declared ``noise_max``) of ``bound='phase'`` over the ellipsoid's on the same
    samples ``warm`` on, once the scalars hold: (median, max)."""
    import switchobs_core as so

    obs = [so.SwitchedObserver(system, table, "periodic", [cycle], noise_max=noise_max, bound=b)
           for b in ("ellipsoid", "phase")]
    ratio = []
    for k, (t, ch, _, y) in enumerate(stream):
        nb = []
        for o in obs:
            o.update(t, ch, y)
            nb.append(o.envelope().noise_bound)
        if k >= warm and obs[1].rounding.phase.j >= 0:
            ratio.append(nb[1] / nb[0])
    return (float(np.median(ratio)), float(np.max(ratio))) if ratio else (np.nan, np.nan)


def _timed(est: dict, warm: int, samples: int, block: int) -> dict:
    """CPU time per sample of each estimator in interleaved blocks (the order rotated), after ``warm``
    untimed samples: name -> the blocks' times (us per sample)."""
    names = list(est)
    times: dict = {name: [] for name in names}
    for k in range(warm):
        for f in est.values():
            f(k)
    for b, start in enumerate(range(warm, warm + samples - block + 1, block)):
        order = names[b % len(names):] + names[: b % len(names)]
        for name in order:
            f = est[name]
            c = time.process_time_ns()
            for k in range(start, start + block):
                f(k)
            times[name].append((time.process_time_ns() - c) / block / 1e3)
    return times


def bench_cost(M: int, samples: int, block: int, h: float = 1.0, steady: bool = False) -> dict:
    """Median CPU time per sample of each estimator (interleaved blocks; module docstring, item 4);
    ``steady``: every estimator first runs untimed over the table's start-up phases and one period
    (:func:`_steady_from`), so each timed sample revisits a phase."""
    warm = 0
    if steady:
        system, cycle, table, _ = _cost_setup(M, 1, h)
        warm = _steady_from(system, cycle, table)
    system, cycle, table, stream = _cost_setup(M, warm + samples, h)
    est, tables = _estimators(system, cycle, table, stream)
    names = list(est)
    times = _timed(est, warm, samples, block)
    # the table observers must have stayed on the table (a departure would time the online recursion)
    departures = [getattr(o, "kalman_departures", None) for o in tables]
    bd = tables[-1].bounds           # the phase bound over the node's (the ellipsoid), the timed samples
    timed = range(warm, warm + samples)
    ratio = [bd["phase"][k] / bd["node"][k] for k in timed if k in bd["phase"] and k in bd["node"]]
    return {"n": system.n, "median_us": {k: float(np.median(v[2:])) for k, v in times.items()},
            "phase_ratio": (float(np.median(ratio)), float(np.max(ratio))) if ratio else (np.nan, np.nan),
            "phase_on": float(np.mean([bd["on"][k] for k in timed if k in bd["on"]])),
            "phase_noise_ratio": noise_tightness(system, cycle, table, stream, warm),
            "phase_constants_cpu": tables[-1].constants_cpu,
            "blocks": len(times[names[0]]) - 2, "departures": departures,
            "source": [getattr(o, "gains_source", "?") for o in tables]}


def cost_report(rows: list[dict], label: str) -> str:
    """The markdown of ``--cost``: medians per n, growth exponents, the cost goals at the largest n."""
    names = list(rows[0]["median_us"])
    ns = [r["n"] for r in rows]
    lines = [f"| estimator (us per sample, median) | {' | '.join(f'n = {n}' for n in ns)} | exponent p |",
             "|---|" + "---|" * (len(ns) + 1)]
    for name in names:
        v = [r["median_us"][name] for r in rows]
        p = float(np.polyfit(np.log(ns), np.log(v), 1)[0]) if len(ns) > 1 else float("nan")
        lines.append(f"| {name} | {' | '.join(f'{x:.1f}' for x in v)} | {p:.2f} |")
    if "filterpy KalmanFilter" not in names:
        lines.append(f"| filterpy KalmanFilter | {' | '.join('not installed' for _ in ns)} | - |")
    last = rows[-1]["median_us"]
    ref = last["reference Kalman filter (standard form, numpy)"]
    goals = [
        ("table + exact bound + envelope() <= 1/3 of the reference", last["kalman table + envelope() (the node)"] / ref,
         1 / 3),
        ("table without the bound <= 3x the floor",
         last["kalman table, rounding_bound=False"] / last["bare floor x = F x + K (y - H x)"], 3.0),
        ("kalman-online <= 1.5x the reference", last["kalman-online, exact bound"] / ref, 1.5),
    ]
    lines += ["", f"| goal at n = {ns[-1]} | ratio ({label}) | status |", "|---|---|---|"]
    lines += [f"| {g} | {r:.2f} | {'met' if r <= lim else '**not met**'} |" for g, r, lim in goals]
    lines.append(f"| (table + envelope(amortised=False) / reference) | "
                 f"{last['kalman table + envelope(amortised=False)'] / ref:.2f} | - |")
    lines.append(f"| (table with the exact bound / reference) | "
                 f"{last['kalman table, exact bound'] / ref:.2f} | - |")
    # the node pattern against the reference at every n, the ellipsoid and bound='phase'
    node, pha = "kalman table + envelope() (the node)", "kalman table + envelope(), bound='phase'"
    refn = "reference Kalman filter (standard form, numpy)"
    lines += ["", "| node pattern over the reference | " + " | ".join(f"n = {n}" for n in ns) + " |",
              "|---|" + "---|" * len(ns)]
    for name in (node, pha):
        lines.append(f"| {name} | " + " | ".join(f"{r['median_us'][name] / r['median_us'][refn]:.2f}" for r in rows)
                     + " |")
    lines.append("| bound='phase' / the ellipsoid's exact bound: median (max) | "
                 + " | ".join(f"{r['phase_ratio'][0]:.2f} ({r['phase_ratio'][1]:.2f})" for r in rows) + " |")
    lines.append("| its noise bound (noise_max 1 mm) / the ellipsoid's: median (max) | "
                 + " | ".join(f"{r['phase_noise_ratio'][0]:.2f} ({r['phase_noise_ratio'][1]:.2f})" for r in rows)
                 + " |")
    lines.append("| timed samples on the phase path | " + " | ".join(f"{100 * r['phase_on']:.0f} %" for r in rows)
                 + " |")
    lines.append("| bound='phase': constants proved at construction (CPU) | "
                 + " | ".join(f"{r['phase_constants_cpu']:.2f} s" for r in rows) + " |")
    return "\n".join(lines) + "\n"


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
    ap.add_argument("--cost", action="store_true", help="only the online cost per sample (item 4)")
    ap.add_argument("--cost-agents", type=int, nargs="+", default=[2, 8, 16, 32])
    ap.add_argument("--samples", type=int, default=1000, help="--cost: samples per n (default 1000, 20 s)")
    ap.add_argument("--block", type=int, default=25, help="--cost: samples per timed block (default 25)")
    ap.add_argument("--label", default="", help="--cost: what code is measured (default: its git commit)")
    ap.add_argument("--steady", action="store_true",
                    help="--cost: time after every phase of the table was visited once (start-up and one period)")
    ap.add_argument("--before", type=Path, default=None,
                    help="--cost: a checkout to compare with (e.g. /tmp/base9): the node pattern, the table without "
                         "a bound and the reference of both trees, one child process each, interleaved rounds")
    ap.add_argument("--rounds", type=int, default=3, help="--before: rounds (default 3)")
    ap.add_argument("--child", type=Path, default=None, help=argparse.SUPPRESS)
    ap.add_argument("--cache", type=Path, default=None, help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    if a.child is not None:
        import json

        import switchobs_core
        from switchobs_core.threads import single_threaded_blas

        assert switchobs_core.__file__.startswith(str(a.child)), switchobs_core.__file__

        single_threaded_blas()
        from _scale_before import bench_cost_lean

        print(json.dumps(bench_cost_lean(a.cost_agents[0], a.samples, a.block, a.cache)))
        return 0
    if a.cost and a.before is not None:
        from _scale_before import main_before

        return main_before(a)
    if a.cost:
        return main_cost(a)
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
        f"### Scaling with the number of agents, {_dt.date.today().isoformat()}",
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


def main_cost(a: argparse.Namespace) -> int:
    """``--cost``: item 4 of the module docstring."""
    import switchobs_core
    from switchobs_core.threads import single_threaded_blas

    single_threaded_blas()
    src = Path(switchobs_core.__file__).resolve().parents[1]
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True,
                            cwd=src).stdout.strip() or "?"
    label = a.label or f"commit {commit}"
    load0 = os.getloadavg()
    rows = []
    for M in sorted(a.cost_agents):
        c = time.process_time()
        rows.append(bench_cost(M, a.samples, a.block, steady=a.steady))
        print(f"M={M} (n={rows[-1]['n']}): {time.process_time() - c:.1f} s CPU, table departures "
              f"{rows[-1]['departures']}, last gains from {rows[-1]['source']}, "
              + ", ".join(f"{k}: {v:.1f} us" for k, v in rows[-1]["median_us"].items()), file=sys.stderr, flush=True)
    load1 = os.getloadavg()
    text = (f"Machine: {_machine()}; {label} (switchobs_core from {src}); load average {load0[0]:.1f} before, "
            f"{load1[0]:.1f} after; {a.samples} samples per n in blocks of {a.block} "
            + ("after the table's start-up and one period, untimed (--steady) " if a.steady else "")
            + f"({rows[0]['blocks']} blocks in the medians).\n\n" + cost_report(rows, label))
    print(text)
    if a.out:
        a.out.write_text(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
