#!/usr/bin/env python
"""Start-up to the first estimate: the estimator with a cached table against a bare rclpy node.

    python bench/bench_startup.py [--rounds 3] [--systems paper,agents32] [--table32 FILE] [--floor] [--early]
                                  [--before DIR] [--before-version 3] [--channel-type TYPE] [--script]
                                  [--discovery-profile FILE]

Per system a camera_sim publishes throughout (50 Hz, the system's periodic schedule, the channel
stamped); in turn, interleaved over ``--rounds`` rounds (the order rotated each round), this process
starts

* ``bare``: the bare rclpy republisher of ``bench/bench_node.py`` (imports rclpy and numpy, one
  subscription per input, republishes every target pose);
* ``estimator``: ``python -m switchobs_ros.estimator`` (with ``--script``, as its console script
  ``ros2 run switchobs_ros estimator`` starts it: :func:`switchobs_ros.entry.estimator`, which
  creates the node's DDS participant before its imports; ``python -m`` starts the same way where the
  ``estimator`` module hands over to it when run as ``__main__``) with the system and its table already on disk
  (``gain_table``): the paper's LMI table (JSON), or the 251 MiB Kalman table of ``camera_agents``
  with 32 agents (n = 132, 1 600 phases, ``.npz``; designed here unless ``--table32`` names one;
  written here in the binary container's current version),

with ``--early``, ``early``: this estimator started by ``bench/startup_early_driver.py``, which creates
the process's DDS participant (a bare node) before importing the estimator, so that discovery runs
during the imports and the table's load (an experiment; the node's own entry point does not);
with ``--floor``, ``floor``: the same bare republisher that first imports what every estimator start
needs of scipy (``scipy.linalg``, ``scipy.sparse``: the runtime's BLAS/LAPACK wrappers, matrix
exponentials, sparse transitions; ``scipy.special`` only with the chi-square gate), the least any estimator
start built on scipy takes; and, with ``--before DIR``, the same estimator from another checkout
(``PYTHONPATH=DIR``; the same 32-agent table, or with ``--before-version 3`` the table written in
version 3 of the container for a checkout that reads only that).

The goal's measure, printed first: the wall time from the start of the process (just before it is
spawned) to the arrival here of its first answer (``/estimator/state``, the republisher's ``~/out``),
the estimator's median over the bare republisher's, goal <= 2x. The table beside it gives, per node,
that time's median and range over the starts, the ratio of each round's start to the bare start of
the same round (median and range), the wall time to the node being ready (its log line once its
publishers and subscriptions exist: ``estimator ready``, ``bare_republisher ready``), the node's CPU
time (user + system) then, the CPU time at its first answer, and each start's first answer in round
order. The first answer also waits for DDS discovery: a node that starts finds camera_sim (and this
process) at once in some starts, in the others only at their next participant announcement (Fast
DDS: every 3 s by default), so the same start answers after about 0.7 s or 3.7 s. ``--discovery-profile``
runs this process, camera_sim and every node with that Fast DDS profile
(``FASTRTPS_DEFAULT_PROFILES_FILE``, e.g. ``config/fastdds_discovery.xml``: announcements every
0.5 s); ``--channel-type`` sets the estimator's ``channel_type``. Every child writes its bytecode to a
private ``PYTHONPYCACHEPREFIX`` (an installed package has its ``.pyc``; this checkout is run with
``PYTHONDONTWRITEBYTECODE``), warmed by one unmeasured start of each.

Goal: the estimator with a cached table of any size <= 2x the bare node.
A script, not a test: nothing is asserted.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

import yaml

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "bench"))

from bench_design import machine_info  # noqa: E402
from bench_live_scale import cpu_seconds  # noqa: E402

from switchobs_core.table.container import encode  # noqa: E402
from switchobs_core.table.io import table_payload  # noqa: E402
from switchobs_core.threads import single_threaded_blas  # noqa: E402

single_threaded_blas()

import rclpy  # noqa: E402
from geometry_msgs.msg import PoseStamped  # noqa: E402
from rclpy.node import Node  # noqa: E402
from std_msgs.msg import Float64MultiArray  # noqa: E402

import switchobs_core as so  # noqa: E402
from switchobs_ros import qos  # noqa: E402
from tools.domain import claim_domain  # noqa: E402
from tools.launch import NodeProcess, ros_args  # noqa: E402


class First(Node):
    """Records when the first message arrives on one topic."""

    def __init__(self, topic: str, kind: type):
        super().__init__("startup_probe")
        self.at: float | None = None
        self.create_subscription(kind, topic, self._got, qos.OUTPUT)

    def _got(self, _msg) -> None:
        if self.at is None:
            self.at = time.monotonic()


#: The bare republisher after importing the scipy modules every estimator start needs (``--floor``).
FLOOR = ("import sys; sys.path.insert(0, {bench!r}); import scipy.linalg, scipy.sparse; "
         "from bench_node import republisher_main; republisher_main()")

#: The line each node writes once its subscriptions and publishers exist.
READY = {"bare": "bare_republisher ready", "floor": "bare_republisher ready", "estimator": "estimator ready",
         "early": "estimator ready"}


#: ``--script``: the estimator started as its console script (``ros2 run switchobs_ros estimator``) starts it.
SCRIPT = "import sys; from switchobs_ros.entry import estimator; sys.exit(estimator())"


def one_start(kind: str, params: dict, env: dict, log: Path, timeout: float = 120.0,
              script: bool = False) -> tuple[float, ...]:
    """(wall seconds to ready, the node's CPU seconds then, wall seconds to the first answer, CPU then) of
    one start."""
    if kind in ("bare", "floor"):
        topic, mtype = "/bare_republisher/out", PoseStamped
        probe = First(topic, mtype)
        t0 = time.monotonic()
        cmd = [sys.executable, str(REPO / "bench" / "bench_node.py"), "--republisher"] if kind == "bare" else \
            [sys.executable, "-c", FLOOR.format(bench=str(REPO / "bench"))]
        node = NodeProcess(kind, cmd=cmd, log=log, env=env)
    else:
        topic, mtype = "/estimator/state", Float64MultiArray
        probe = First(topic, mtype)
        t0 = time.monotonic()
        cmd = [sys.executable, str(REPO / "bench" / "startup_early_driver.py")] if kind == "early" else \
            [sys.executable, "-c", SCRIPT] if script else None
        node = NodeProcess("estimator", ros_args(params=params), cmd=cmd, log=log, env=env)
    ready = ready_cpu = float("nan")
    try:
        end = t0 + timeout
        while probe.at is None and time.monotonic() < end and node.alive():
            rclpy.spin_once(probe, timeout_sec=0.002)
            if ready != ready and READY[kind] in log.read_text(errors="replace"):
                ready, ready_cpu = time.monotonic() - t0, cpu_seconds(node.pid)
        cpu = cpu_seconds(node.pid) if node.alive() else float("nan")
        wall = (probe.at - t0) if probe.at is not None else float("nan")
    finally:
        node.stop()
        probe.destroy_node()
    return ready, ready_cpu, wall, cpu


def headline(rows: list) -> str:
    """The goal's ratio: the estimator's wall time from its process start to its first estimate over
    the bare republisher's to its first republished message (medians over the starts of one run)."""
    parts = []
    for name, _, times in rows:
        first = {k: statistics.median(r[2] for r in v) for k, v in times.items()}
        cpu = {k: statistics.median(r[1] for r in v) for k, v in times.items()}
        others = "".join(f", {k} {first[k] / first['bare']:.2f}x" for k in first if k not in ("bare", "estimator"))
        parts.append(f"- {name}: **{first['estimator'] / first['bare']:.2f}x** ({first['estimator']:.2f} s against "
                     f"{first['bare']:.2f} s{others}); CPU to ready {cpu['estimator'] / cpu['bare']:.2f}x")
    n = min(len(v) for _, _, times in rows for v in times.values())
    return ("Goal 6, start-up: wall time from the process start to the first estimate received, over the bare "
            f"node's to its first republished message (medians of {n} starts each, goal <= 2x):\n"
            + "\n".join(parts) + "\n")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--systems", default="paper,agents32", help="comma-separated: paper, agents32")
    ap.add_argument("--floor", action="store_true", help="also the bare republisher after scipy's imports")
    ap.add_argument("--early", action="store_true", help="also this estimator with its DDS participant created "
                                                        "before its imports (bench/startup_early_driver.py)")
    ap.add_argument("--before", default="", help="another checkout whose estimator runs beside this one's")
    ap.add_argument("--before-version", type=int, default=0, help="the container version of the 32-agent table "
                    "the --before checkout reads (default: the same file as this checkout's; 3 for a checkout "
                    "that reads only version 3)")
    ap.add_argument("--script", action="store_true", help="start the estimator (and --before's) as its console "
                    "script does (switchobs_ros.entry.estimator) instead of python -m switchobs_ros.estimator")
    ap.add_argument("--domain", type=int, default=None, help="the ROS_DOMAIN_ID to run in (default: a free one "
                                                                 "claimed from 1..100)")
    ap.add_argument("--channel-type", default="", help="the estimator's channel_type (default: its own default)")
    ap.add_argument("--discovery-profile", default="", help="a Fast DDS XML profile for this process and every "
                                                            "node (FASTRTPS_DEFAULT_PROFILES_FILE)")
    ap.add_argument("--table32", default="", help="an existing 32-agent Kalman table (.npz) of camera_agents, "
                                                  "every h = 1 s, 50 Hz (designed here if empty)")
    a = ap.parse_args(argv)
    info = machine_info()
    lease = claim_domain() if a.domain is None else None
    os.environ["ROS_DOMAIN_ID"] = str(lease.domain_id if lease is not None else a.domain)
    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    if a.discovery_profile:     # read by Fast DDS when this process's participant is created (rclpy.init)
        os.environ["FASTRTPS_DEFAULT_PROFILES_FILE"] = str(Path(a.discovery_profile).resolve())
    rows = []
    with tempfile.TemporaryDirectory(prefix="bench_startup_") as tmp:
        d = Path(tmp)
        env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
        # PYTHONSAFEPATH: `python -m` does not put the working directory first on sys.path (--before runs
        # the other checkout's estimator, not this one's)
        env.update(PYTHONPYCACHEPREFIX=str(d / "pyc"), OPENBLAS_NUM_THREADS="1", PYTHONSAFEPATH="1",
                   PYTHONPATH=str(REPO))
        setups = {}
        tables_before: dict[str, str] = {}
        for name in a.systems.split(","):
            if name == "paper":
                system = so.load_system("paper")
                table = so.design_table(system, [so.Cycle.from_ts(2.0, 0.6)]).save(d / "paper.json")
                sched = {"schedule.mode": "periodic", "schedule.tau": [2.0], "schedule.s": [0.6]}
                setups[name] = (dict(sched, system="paper"), dict(sched, system="paper", gain_table=str(table)))
            elif name == "agents32":
                sys_path = d / "agents32.yaml"
                sys_path.write_text(yaml.safe_dump({"scenario": "camera_agents", "agents": 32}))
                system = so.load_system(sys_path)
                if a.table32:
                    k32 = so.GainTable.load(a.table32, system=system)
                else:
                    k32 = so.kalman_table(system, [so.design_kalman(system, so.Cycle([1.0] * 32), 50.0)])
                table = str(k32.save(d / "k32.npz"))
                if a.before_version:                            # what a checkout before version 4 reads
                    with open(d / "k32_before.npz", "wb") as fh:
                        encode(table_payload(k32), fh, version=a.before_version)
                    tables_before[name] = str(d / "k32_before.npz")
                del k32
                sched = {"schedule.mode": "periodic", "schedule.h": [1.0] * 32}
                setups[name] = (dict(sched, system=str(sys_path)), dict(sched, system=str(sys_path), gain_table=table))
            else:
                raise SystemExit(f"unknown system {name!r}")
            if a.channel_type:
                setups[name][1]["channel_type"] = a.channel_type
        rclpy.init()
        try:
            for name, (cam_params, est_params) in setups.items():
                cam = NodeProcess("camera_sim", ros_args(params=dict(cam_params, rate=50.0)), log=d / f"cam_{name}.log",
                                  env=env)
                try:
                    size = Path(est_params["gain_table"]).stat().st_size
                    kinds = {"bare": env, "estimator": env}
                    if a.floor:
                        kinds["floor"] = env
                    if a.early:
                        kinds["early"] = env
                    if a.before:
                        kinds["before"] = dict(env, PYTHONPATH=a.before, PYTHONPYCACHEPREFIX=str(d / "pyc_before"))
                    times: dict[str, list[tuple[float, ...]]] = {k: [] for k in kinds}
                    for r in range(a.rounds + 1):           # round 0 warms the bytecode and the page cache
                        order = list(kinds)[r % len(kinds):] + list(kinds)[:r % len(kinds)]     # rotated
                        for kind in order:
                            kind_env = kinds[kind]
                            params = est_params
                            if kind == "before" and name in tables_before:
                                params = dict(est_params, gain_table=tables_before[name])
                            res = one_start(kind if kind in ("bare", "floor", "early") else "estimator", params,
                                            kind_env,
                                            d / f"{name}_{kind}_{r}.log", script=a.script)
                            if r:
                                times[kind].append(res)
                    rows.append((name, size, times))
                finally:
                    cam.stop()
        finally:
            rclpy.try_shutdown()
            if lease is not None:
                lease.release()
    print(f"Machine: {info['cpu']}, {info['nproc']} cores, Python {info['python']}; commit {info['commit']}; "
          f"load average {info['load'][0]:.1f} before ({info['date']}).")
    before = " --floor" if a.floor else ""
    before += " --early" if a.early else ""
    before += " --script" if a.script else ""
    before += f" --before {a.before}" if a.before else ""
    before += f" --before-version {a.before_version}" if a.before_version else ""
    before += f" --channel-type {a.channel_type}" if a.channel_type else ""
    before += f" --discovery-profile {a.discovery_profile}" if a.discovery_profile else ""
    print(f"Command: `OPENBLAS_NUM_THREADS=1 python bench/bench_startup.py --rounds {a.rounds} --systems {a.systems}"
          f"{before}`\n")
    print(headline(rows))
    print("| system (table size) | node | wall to the first answer: median [min, max] | / bare (goal <= 2) | "
          "per round / bare: median [min, max] | wall to ready | / bare | CPU to ready | / bare | "
          "CPU at the first answer |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for name, size, times in rows:
        med = {k: [statistics.median(r[i] for r in v) for i in range(4)] for k, v in times.items()}
        b = med["bare"]
        for kind, (rw, rc, fw, fc) in med.items():
            firsts = [r[2] for r in times[kind]]
            per = [r[2] / q[2] for r, q in zip(times[kind], times["bare"])]
            print(f"| {name} ({size / 2**20:.1f} MiB) | {kind} | {fw:.2f} s [{min(firsts):.2f}, {max(firsts):.2f}] "
                  f"| {fw / b[2]:.2f}x | {statistics.median(per):.2f}x [{min(per):.2f}, {max(per):.2f}] "
                  f"| {rw:.2f} s | {rw / b[0]:.2f}x | {rc:.2f} s | {rc / b[1]:.2f}x | {fc:.2f} s |")
    print("\nWall time to the first answer, each start in round order (s):")
    for name, _, times in rows:
        for kind, v in times.items():
            print(f"- {name} {kind}: " + ", ".join(f"{r[2]:.2f}" for r in v))
    return 0


if __name__ == "__main__":
    sys.exit(main())
