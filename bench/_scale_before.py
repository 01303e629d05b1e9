"""``bench_scale.py --cost --before TREE``: the node pattern of this checkout and of another tree side by
side (:func:`main_before`), each ``(tree, M)`` a child process of ``bench_scale.py --child`` with
``PYTHONPATH`` at the tree (:func:`bench_cost_lean`)."""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
from bench_scale import PY, REPO, ReferenceKF, _cost_setup, _machine, _steady_from, _timed

SCRIPT = Path(__file__).resolve().with_name("bench_scale.py")

#: The estimators a ``--before`` child times (the node pattern, the table without a bound, the reference).
LEAN = ("kalman table + envelope() (the node)", "kalman table, rounding_bound=False",
        "reference Kalman filter (standard form, numpy)")


def _lean_estimators(system, cycle, table, stream) -> tuple[dict, list, list]:
    """(the :data:`LEAN` estimators of :func:`_estimators`, their two table observers, the list the node
    pattern appends its exact bound to): a ``--before`` child's."""
    import switchobs_core as so

    noise = so.default_noise(system)
    env = so.SwitchedObserver(system, table, "periodic", [cycle])
    nob = so.SwitchedObserver(system, table, "periodic", [cycle], rounding_bound=False)
    ref = ReferenceKF(np.asarray(system.A, dtype=float), noise.Q_c, noise.P0, noise.R(1))
    bounds: list = []
    return {LEAN[0]: lambda k: (env.update(stream[k][0], stream[k][1], stream[k][3]),
                                bounds.append(env.envelope().exact_bound)),
            LEAN[1]: lambda k: nob.update(stream[k][0], stream[k][1], stream[k][3]),
            LEAN[2]: lambda k: ref.update(stream[k][0], stream[k][2], stream[k][3])}, [env, nob], bounds



def bench_cost_lean(M: int, samples: int, block: int, cache: Path, h: float = 1.0) -> dict:
    """``--before``'s child: the :data:`LEAN` estimators after the table's start-up and one period
    (``--steady``), the table from ``cache``; medians per estimator and the node's exact bounds of the
    timed samples (for the comparison of the trees' bounds)."""
    system, cycle, table, _ = _cost_setup(M, 1, h, cache=cache)
    warm = _steady_from(system, cycle, table)
    system, cycle, table, stream = _cost_setup(M, warm + samples, h, cache=cache)
    est, obs, bounds = _lean_estimators(system, cycle, table, stream)
    times = _timed(est, warm, samples, block)
    return {"n": system.n, "median_us": {k: float(np.median(v[2:])) for k, v in times.items()},
            "bounds": bounds[warm:], "departures": [getattr(o, "kalman_departures", None) for o in obs]}


def main_before(a: argparse.Namespace) -> int:
    """``--cost --before TREE``: the :data:`LEAN` estimators of this checkout and of ``TREE``, each
    ``(tree, M)`` a child process (this script, ``PYTHONPATH`` at the tree), the trees alternating
    in each round; the node pattern over the reference per child (the same reference code in both),
    medians over the rounds, and the ratio of the trees' node patterns. The children share one
    Kalman table per ``M`` (designed by the first, saved, then loaded). The trees' exact bounds on
    the same samples are compared too (this / before: median and range)."""
    import json

    trees = [("this", REPO), ("before", a.before.resolve())]
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1")
    load0 = os.getloadavg()
    res: dict = {}
    with tempfile.TemporaryDirectory(prefix="bench_scale_before_") as td:
        for r in range(a.rounds):
            for M in sorted(a.cost_agents):
                for name, tree in (trees if r % 2 == 0 else trees[::-1]):
                    cmd = [PY, str(SCRIPT), "--cost", "--child", str(tree), "--cache", td, "--cost-agents", str(M),
                           "--samples", str(a.samples), "--block", str(a.block)]
                    p = subprocess.run(cmd, env=dict(env, PYTHONPATH=str(tree)), capture_output=True, text=True,
                                       cwd=REPO)
                    if p.returncode:
                        sys.exit(f"child {name} M={M} failed:\n{p.stderr[-4000:]}")
                    out = json.loads(p.stdout.strip().splitlines()[-1])
                    res.setdefault((name, M), []).append(out)
                    print(f"round {r} {name} M={M}: " + ", ".join(f"{k}: {v:.1f} us"
                                                                 for k, v in out["median_us"].items())
                          + f", departures {out['departures']}", file=sys.stderr, flush=True)
    load1 = os.getloadavg()
    Ms = sorted(a.cost_agents)
    ns = [res[("this", M)][0]["n"] for M in Ms]
    node, nob, ref = LEAN

    def med(name, M, key):
        return float(np.median([o["median_us"][key] for o in res[(name, M)]]))

    def ratio(name, M):
        return float(np.median([o["median_us"][node] / o["median_us"][ref] for o in res[(name, M)]]))

    lines = [f"Command: `OPENBLAS_NUM_THREADS=1 python bench/bench_scale.py --cost --steady --cost-agents "
             f"{' '.join(map(str, Ms))} --before {a.before} --rounds {a.rounds}` ({a.samples} samples per n in blocks "
             f"of {a.block} after the table's start-up and one period; load average {load0[0]:.1f} before, "
             f"{load1[0]:.1f} after; machine {_machine()})", "",
             "| us per sample, median over the rounds | " + " | ".join(f"n = {n}" for n in ns) + " |",
             "|---|" + "---|" * len(ns)]
    for name in ("this", "before"):
        for key, label in ((node, "kalman table + envelope() (the node)"), (nob, "kalman table, no bound"),
                           (ref, "reference Kalman filter")):
            lines.append(f"| {name}: {label} | " + " | ".join(f"{med(name, M, key):.1f}" for M in Ms) + " |")
    for name in ("this", "before"):
        lines.append(f"| **{name}: node pattern / reference** (per round, median) | "
                     + " | ".join(f"**{ratio(name, M):.2f}**" for M in Ms) + " |")
    lines.append("| node pattern this / before (the medians) | "
                 + " | ".join(f"{med('this', M, node) / med('before', M, node):.2f}" for M in Ms) + " |")
    tight = []
    for M in Ms:
        bt, bb = np.array(res[("this", M)][0]["bounds"]), np.array(res[("before", M)][0]["bounds"])
        q = bt / bb - 1.0
        tight.append(f"{np.median(q):+.1e} [{q.min():+.1e}, {q.max():+.1e}]")
    lines.append("| exact bound this / before - 1, same samples: median [min, max] | " + " | ".join(tight) + " |")
    text = "\n".join(lines) + "\n"
    print(text)
    if a.out:
        a.out.write_text(text)
    return 0
