#!/usr/bin/env python
"""Replay at scale: ``switchobs_bag estimate`` against a numpy Kalman filter script on the same bag.

    python bench/bench_replay.py [--durations 10 20] [--rounds 3] [--agents 32]

A bag of ``camera_agents(M)`` with every velocity mode 0.05/s (n = 4 (M + 1); M = 32: n = 132),
periodic ``periodic-h:1,...,1``, 50 Hz, noise 1 mm, from ``switchobs_bag generate`` (mcap), for each
of ``--durations`` simulated seconds; an LMI gain table designed for that cycle. Each command runs
as a subprocess (``--rounds`` rounds, the two interleaved); per command the child's CPU time (user +
system) and its peak resident memory (``ru_maxrss``), medians over the rounds:

* ``switchobs_bag estimate BAG -o OUT --csv FILE`` (the estimator's pipeline; the output bag with
  the inputs copied, and the CSV; covariance published, its default; the outputs ``--outputs`` writes by
  default: all but ``~/covariance``, whose numbers ``~/state_estimate`` carries);
* the same with ``--outputs all`` (``~/covariance`` too: the command's default before ``--outputs``);
* the alternative, a script of the usual kind (:data:`KF_SCRIPT`): read the bag
  (``switchobs_ros.bag.io.BagIn``), decode the channel and the poses (the same CDR fast path), a
  Kalman filter in standard form in numpy (discretisation cached, Joseph update), a CSV row of the
  estimate per tick.

Goal: CPU <= 2x the script's; memory flat in the recording's length (the growth per
simulated second is printed). A script, not a test: nothing is asserted.

``--noise-max V`` declares ``noise.max`` (m) to the estimate commands (``-p noise.max:=V``; 6 mm
for the bag's 1 mm noise): the bounds then hold throughout and the rigorous sets (the exact and
the noise set) are stepped every tick; without it the first noisy sample withdraws them and the
sets rest. The rows of each estimate run's CSV whose bound is withdrawn (-1) are counted and printed.

Bytecode is cached as an installed package has it: the children write and read it under a
cache folder of the run's own (``PYTHONPYCACHEPREFIX``, whatever ``PYTHONDONTWRITEBYTECODE`` says;
no checkout is written to), after one untimed warm-up run of each command on a 1 s bag.
``--no-bytecode`` keeps the environment's setting (with ``PYTHONDONTWRITEBYTECODE=1`` every run
compiles the modules of a checkout that has no ``__pycache__``: about 0.3 s of each estimate run).
"""

from __future__ import annotations

import argparse
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
#: PYTHONSAFEPATH: ``python -m`` and ``-c`` do not put the working directory first on ``sys.path``, so each
#: command runs the checkout its PYTHONPATH names (``--before``), not the one the benchmark was started in.
ENV = dict(os.environ, PYTHONPATH=str(REPO), OPENBLAS_NUM_THREADS="1", PYTHONSAFEPATH="1")

#: The alternative: a numpy Kalman filter over the bag's camera and target poses, CSV out.
KF_SCRIPT = r"""
import sys
import numpy as np
from scipy.linalg import expm
from switchobs_ros.bag.io import BagIn
from switchobs_ros.bag.cdr import decode_pose, decode_uint8
from switchobs_core.model.scenarios import load_system
from switchobs_core.model.noise import default_noise

system = load_system(sys.argv[2])
n = system.n
A = np.asarray(system.A)
noise = default_noise(system)
Qc, R0 = noise.Q_c, None
x, P = np.zeros(n), noise.P0.copy()
I = np.eye(n)
disc = {}
ch, cam, t_prev = 1, None, None
with BagIn(sys.argv[1]) as bag, open(sys.argv[3], "w") as out:
    out.write("stamp_ns," + ",".join(system.state_labels) + "\n")
    for m in bag.messages(order="file"):
        if m.topic == "/camera/active_channel":
            ch = int(decode_uint8(m.data, None).data)
        elif m.topic == "/camera/pose":
            cam = decode_pose(m.data, None)
        elif m.topic == "/target/pose" and cam is not None:
            tgt = decode_pose(m.data, None)
            t = tgt.header.stamp.sec + 1e-9 * tgt.header.stamp.nanosec
            H = np.asarray(system.C[ch - 1])
            y = np.array([cam.pose.position.x, cam.pose.position.y,
                          tgt.pose.position.x - cam.pose.position.x, tgt.pose.position.y - cam.pose.position.y])
            y = y[:H.shape[0]]
            R = noise.R(ch)
            if t_prev is not None and t > t_prev:
                key = round((t - t_prev) * 1e9)
                if key not in disc:
                    V = expm(np.block([[A, Qc], [np.zeros((n, n)), -A.T]]) * (t - t_prev))
                    disc[key] = (V[:n, :n], V[:n, n:] @ V[:n, :n].T)
                F, Qd = disc[key]
                x = F @ x
                P = F @ P @ F.T + Qd
            t_prev = t
            PHt = P @ H.T
            K = PHt @ np.linalg.inv(H @ PHt + R)
            x = x + K @ (y - H @ x)
            IKH = I - K @ H
            P = IKH @ P @ IKH.T + K @ R @ K.T
            P = 0.5 * (P + P.T)
            ns = tgt.header.stamp.sec * 1000000000 + tgt.header.stamp.nanosec
            out.write(f"{ns}," + ",".join(map(repr, x.tolist())) + "\n")
"""


def peak(cmd: list[str], repo: Path = REPO) -> tuple[float, float, float]:
    """(CPU seconds, peak RSS MiB, system CPU seconds) measured in a wrapper process of its own (``ru_maxrss``
    of RUSAGE_CHILDREN is the largest over all children so far, so each measurement gets a fresh parent).
    The system part is mostly the kernel copying the output bag into the page cache (500 MB a minute of a
    32-agent bag): it depends on the machine's memory as much as on the command (bench/RESULTS.md, replay11)."""
    code = ("import resource, subprocess, sys; r = subprocess.run(sys.argv[1:]); "
            "u = resource.getrusage(resource.RUSAGE_CHILDREN); "
            "print(u.ru_utime + u.ru_stime, u.ru_maxrss / 1024.0, u.ru_stime); sys.exit(r.returncode)")
    r = subprocess.run([sys.executable, "-c", code, *cmd], env=dict(ENV, PYTHONPATH=str(repo)), capture_output=True,
                       text=True)
    if r.returncode:
        raise SystemExit(f"{cmd[:4]} failed: {r.stderr[-2000:]}")
    cpu, rss, sys_cpu = r.stdout.split()[-3:]
    return float(cpu), float(rss), float(sys_cpu)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--durations", type=float, nargs="+", default=[10.0, 20.0])
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--agents", type=int, default=32)
    ap.add_argument("--before", type=Path, default=None,
                    help="also run the estimate command of another checkout (e.g. the main branch), same bags")
    ap.add_argument("--no-all", action="store_true", help="skip the runs with --outputs all (7 MB/s of covariance)")
    ap.add_argument("--noise-max", type=float, default=None, metavar="V",
                    help="declare noise.max (m) to the estimate commands: bounds that hold throughout")
    ap.add_argument("--no-bytecode", action="store_true",
                    help="keep the environment's bytecode setting (no private cache, no warm-up run)")
    a = ap.parse_args()
    sys.path.insert(0, str(REPO))
    from switchobs_core.threads import single_threaded_blas

    single_threaded_blas()
    from switchobs_core.design.lmi import design_table
    from switchobs_core.model.scenarios import load_system
    from switchobs_core.model.schedule import Cycle
    from switchobs_ros.bag.generate import GenerateConfig, generate

    M = a.agents
    work = Path(tempfile.mkdtemp(prefix="switchobs_bench_replay_"))
    if not a.no_bytecode:
        ENV.pop("PYTHONDONTWRITEBYTECODE", None)
        ENV["PYTHONPYCACHEPREFIX"] = str(work / "pycache")
    sysf = work / "system.yaml"
    sysf.write_text(f"scenario: camera_agents\nagents: {M}\nD_agents: {[[0.0, 0.05]] * M}\n")
    system = load_system(str(sysf))
    table = design_table(system, [Cycle([1.0] * M)], progress=False).save(work / "gains.json")
    sched = "periodic-h:" + ",".join(["1"] * M)
    bags = {}
    for d in ([] if a.no_bytecode else [1.0]) + list(a.durations):
        bags[d] = work / f"in{d:g}"
        generate(bags[d], GenerateConfig(system=str(sysf), schedule=sched, rate=50.0, duration=d,
                                         noise_std=1e-3), "mcap")
    exe = [sys.executable, "-m", "switchobs_ros.bag"]
    ours: dict = {d: [] for d in a.durations}
    ours_all: dict = {d: [] for d in a.durations}
    alt: dict = {d: [] for d in a.durations}
    before: dict = {d: [] for d in a.durations}

    def est(d, r, tag):
        return [*exe, "estimate", str(bags[d]), "-o", str(work / f"{tag}{d:g}_{r}"), "--csv",
                str(work / f"{tag}{d:g}_{r}.csv"), "--gain-table", str(table), "--system", str(sysf),
                "-p", f"schedule.h:={[1.0] * M}", "--no-progress",
                *([] if a.noise_max is None else ["-p", f"noise.max:={a.noise_max!r}"])]

    withdrawn: dict = {}            # tag -> (rows with a withdrawn bound, rows), over the runs

    def count(tag, d, r):           # the estimate run's CSV: rows whose published bound is -1
        import numpy as np
        rows = np.genfromtxt(work / f"{tag}{d:g}_{r}.csv", delimiter=",", names=True)
        col = rows["noise_bound" if a.noise_max is not None else "exact_bound"]
        w, t = withdrawn.get(tag, (0, 0))
        withdrawn[tag] = (w + int((col < 0).sum()), t + int(col.size))

    def done(*names):           # an output measured is removed at once (100 s with every output: 3.4 GB)
        for name in names:
            shutil.rmtree(work / name, ignore_errors=True)
            (work / name).unlink(missing_ok=True)

    if not a.no_bytecode:       # warm-up: each command once, untimed (its bytecode cached)
        peak(est(1.0, 0, "w"))
        if a.before is not None:
            peak(est(1.0, 0, "v"), a.before)
        peak([sys.executable, "-c", KF_SCRIPT, str(bags[1.0]), str(sysf), str(work / "k.csv")])
    for r in range(a.rounds):
        for d in a.durations:
            ours[d].append(peak(est(d, r, "o")))
            count("o", d, r)
            done(f"o{d:g}_{r}", f"o{d:g}_{r}.csv")
            if not a.no_all:
                ours_all[d].append(peak([*est(d, r, "a"), "--outputs", "all"]))
                done(f"a{d:g}_{r}", f"a{d:g}_{r}.csv")
            if a.before is not None:
                before[d].append(peak(est(d, r, "b"), a.before))
                count("b", d, r)
                done(f"b{d:g}_{r}", f"b{d:g}_{r}.csv")
            alt[d].append(peak([sys.executable, "-c", KF_SCRIPT, str(bags[d]), str(sysf),
                                str(work / f"k{d:g}_{r}.csv")]))
            done(f"k{d:g}_{r}.csv")
    print(f"### Replay of a {M}-agent bag (n = {system.n}), 50 Hz: `switchobs_bag estimate` against a numpy "
          "Kalman filter script\n")
    print(f"`python bench/bench_replay.py --durations {' '.join(f'{d:g}' for d in a.durations)} --rounds "
          f"{a.rounds} --agents {M}{f' --before {a.before}' if a.before else ''}"
          f"{' --no-all' if a.no_all else ''}{' --no-bytecode' if a.no_bytecode else ''}"
          f"{'' if a.noise_max is None else f' --noise-max {a.noise_max:g}'}`; load average at the end "
          f"{os.getloadavg()[0]:.1f}.\n")
    print("Rows with a withdrawn bound: " + ", ".join(f"{'estimate' if k == 'o' else '--before'} {w} of {t}"
                                                      for k, (w, t) in withdrawn.items()) + ".\n")
    print("| bag | estimate: CPU | peak RSS | numpy KF script: CPU | peak RSS | CPU ratio (goal <= 2) | "
          "--outputs all: CPU | ratio |" + (" --before: CPU | peak RSS | ratio | estimate / before, per round |"
                                            if a.before else ""))
    print("|---|---|---|---|---|---|---|---|" + ("---|---|---|---|" if a.before else ""))
    med = {}
    for d in a.durations:
        oc, om = statistics.median(x[0] for x in ours[d]), statistics.median(x[1] for x in ours[d])
        kc, km = statistics.median(x[0] for x in alt[d]), statistics.median(x[1] for x in alt[d])
        med[d] = (oc, om, kc, km)
        ac = statistics.median(x[0] for x in ours_all[d]) if ours_all[d] else float("nan")
        extra = ""
        if a.before:
            bc = statistics.median(x[0] for x in before[d])
            extra = (f" {bc:.2f} s | {statistics.median(x[1] for x in before[d]):.0f} MiB | {bc / kc:.2f}x |"
                     f" {statistics.median(o[0] / b[0] for o, b in zip(ours[d], before[d])):.2f} |")
        print(f"| {d:g} s | {oc:.2f} s | {om:.0f} MiB | {kc:.2f} s | {km:.0f} MiB | {oc / kc:.2f}x | {ac:.2f} s | "
              f"{ac / kc:.2f}x |" + extra)
    print("\nOf the CPU, system time (medians): " + "; ".join(
        f"{d:g} s bag: estimate {statistics.median(x[2] for x in ours[d]):.2f} s, script "
        f"{statistics.median(x[2] for x in alt[d]):.2f} s"
        + (f", --before {statistics.median(x[2] for x in before[d]):.2f} s" if a.before else "") for d in a.durations)
        + ".")
    if len(a.durations) > 1:
        d0, d1 = min(a.durations), max(a.durations)
        g = (med[d1][1] - med[d0][1]) / (d1 - d0)
        gk = (med[d1][3] - med[d0][3]) / (d1 - d0)
        gb = ""
        if a.before:
            b0, b1 = (statistics.median(x[1] for x in before[d]) for d in (d0, d1))
            gb = f", --before {(b1 - b0) / (d1 - d0):.2f} MiB/s"
        print(f"\nMemory growth per simulated second: estimate {g:.2f} MiB/s, script {gk:.2f} MiB/s{gb}.")
    shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
