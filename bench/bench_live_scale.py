#!/usr/bin/env python
"""The estimator node live at scale: 32 agents (n = 132) at 50 Hz over DDS against a bare rclpy
republisher, side by side in one run.

    python bench/bench_live_scale.py                       # 32 agents, 50 Hz, 60 s per node
    python bench/bench_live_scale.py --agents 8 --seconds 20 --nodes kalman,bare

Three processes per run, one role each: camera_sim (the built-in ``camera_agents`` model with M
agents, every h_i = 1 s, stamping each tick on its grid) as the sender; the node under test: the
estimator with the model's Kalman table (``kalman``) or LMI table (``lmi``), all outputs at their
defaults, or the ceiling (``bare``), a bare rclpy node that republishes every target pose
(``bench/bench_node.py --republisher``), or the messaging floor (``sink``, ``bench/sink_node.py``:
the estimator's subscriptions and outputs, no math); a node ``<kind>@rclpy`` spins rclpy's
SingleThreadedExecutor, ``<kind>@events`` rclpy's EventsExecutor, otherwise
``switchobs_ros.executor.KeptWaitSetExecutor`` (``SWITCHOBS_EXECUTOR``); and this process as the
receiver, which only records the arrival of each answer (``/estimator/state``, or the
republisher's ``~/out``) and of each truth message (one per tick: what was sent). Reported per
node: ticks sent, answers, the fraction answered, latency (arrival - the tick's stamp, both this
machine's system clock) p50 and p99, and the node process's CPU time per answer (user + system,
from ``/proc``, from the first tick to the last answer). Ratios against ``bare`` in the same run.
``--threads`` adds the node's CPU per answer by thread name (the Python thread, Fast DDS's
``dds.*`` threads) and its minor page faults; ``--spy DIR`` samples each node with py-spy
``--native`` (``PY_SPY``: its path; it pauses the process at each sample, so the run is slower).

A script, not a test: nothing is asserted.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import yaml

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "bench"))

from bench_design import machine_info  # noqa: E402

from switchobs_core.threads import single_threaded_blas  # noqa: E402

single_threaded_blas()

import rclpy  # noqa: E402
from geometry_msgs.msg import PoseStamped  # noqa: E402
from rclpy.node import Node  # noqa: E402
from std_msgs.msg import Float64MultiArray  # noqa: E402

import msg_bridge as mb  # noqa: E402
import switchobs_core as so  # noqa: E402
from switchobs_ros import qos  # noqa: E402
from tools.domain import claim_domain  # noqa: E402
from tools.launch import NodeProcess, ros_args  # noqa: E402

TICKS = os.sysconf("SC_CLK_TCK")


def cpu_seconds(pid: int) -> float:
    """User + system CPU time of process ``pid`` (and its reaped children not counted)."""
    f = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(f[11]) + int(f[12])) / TICKS


def thread_cpu(pid: int) -> dict[str, list[float]]:
    """Per thread of process ``pid``, grouped by thread name: [user s, system s, minor faults]."""
    out: dict[str, list[float]] = {}
    for task in Path(f"/proc/{pid}/task").iterdir():
        try:
            raw = (task / "stat").read_text()
        except OSError:             # the thread ended
            continue
        name = raw[raw.index("(") + 1:raw.rindex(")")]
        f = raw.rsplit(")", 1)[1].split()
        row = out.setdefault(name, [0.0, 0.0, 0.0])
        row[0] += int(f[11]) / TICKS
        row[1] += int(f[12]) / TICKS
        row[2] += int(f[7])
    return out


def spy(pid: int, seconds: float, out: Path):
    """py-spy (``PY_SPY``, e.g. a scratch venv's) sampling process ``pid`` with native frames."""
    import subprocess
    exe = os.environ.get("PY_SPY", "py-spy")
    return subprocess.Popen([exe, "record", "--native", "-r", "100", "-p", str(pid),
                             "-d", str(int(seconds)), "-f", "raw", "-o", str(out)],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)


class Receiver(Node):
    """Records the arrival time of every answer and every truth message, keyed by stamp; with
    ``optional`` topics, also counts the messages on each (taken raw: not deserialised here)."""

    def __init__(self, answer_topic: str, pose: bool, optional: tuple[tuple[str, type], ...] = ()):
        super().__init__("bench_live_receiver")
        self.answers: dict[int, int] = {}
        self.truth: dict[int, int] = {}
        self.counts: dict[str, int] = dict.fromkeys((t for t, _ in optional), 0)
        if pose:
            self.create_subscription(PoseStamped, answer_topic, self._pose, qos.OUTPUT)
        else:
            self.create_subscription(Float64MultiArray, answer_topic, self._array, qos.OUTPUT)
        self.create_subscription(Float64MultiArray, "/sim/truth", self._truth, qos.TRUTH)
        for topic, kind in optional:
            self.create_subscription(kind, topic, self._counter(topic), qos.OUTPUT, raw=True)

    def _counter(self, topic: str):
        def count(_raw: bytes) -> None:
            self.counts[topic] += 1
        return count

    def _pose(self, m: PoseStamped) -> None:
        self.answers[m.header.stamp.sec * 1_000_000_000 + m.header.stamp.nanosec] = time.time_ns()

    def _array(self, m: Float64MultiArray) -> None:
        self.answers[mb.unpack_labelled(m).stamp_ns] = time.time_ns()

    def _truth(self, m: Float64MultiArray) -> None:
        self.truth[mb.unpack_labelled(m).stamp_ns] = time.time_ns()


def optional_outputs(system) -> tuple[tuple[str, type], ...]:
    """The estimator's outputs besides ``~/state``: (topic, message type)."""
    from nav_msgs.msg import Odometry
    from switchobs_msgs.msg import ErrorBounds, StateEstimate
    from visualization_msgs.msg import MarkerArray
    return (("/estimator/envelope", Float64MultiArray), ("/estimator/covariance", Float64MultiArray),
            ("/estimator/state_estimate", StateEstimate), ("/estimator/error_bounds", ErrorBounds),
            ("/estimator/markers", MarkerArray),
            *((f"/estimator/{b.name}/odom", Odometry) for b in mb.bodies(system.state_labels)))


def run_node(kind: str, m: int, seconds: float, rate: float, sys_path: Path, tables: dict, logs: Path,
             listen: bool = False, every: dict | None = None, profile: Path | None = None,
             main_repo: Path | None = None, threads: bool = False, spy_dir: Path | None = None,
             tag: str = "") -> dict:
    """One node under test: ``listen`` subscribes to every optional output of the estimator,
    ``every`` sets its ``output.*_every``, ``profile`` runs it under cProfile (bench/profile_node.py);
    a ``kind`` ``main:kalman`` runs the estimator of the checkout ``main_repo`` instead of this one;
    ``threads`` records the node's CPU per thread name, ``spy_dir`` samples it with py-spy."""
    repo = REPO
    if kind.startswith("main:"):
        repo = main_repo
    base, _, executor = kind.partition("@")
    env = dict(os.environ, SWITCHOBS_EXECUTOR=executor or "kept")
    log = logs / f"{kind.replace(':', '_').replace('@', '_')}.log"
    sched = {"schedule.mode": "periodic", "schedule.h": [1.0] * m}
    optional = ()
    outputs = {f"output.{k}_every": v for k, v in (every or {}).items()}
    if kind == "bare":
        node = NodeProcess("bare", cmd=[sys.executable, str(REPO / "bench" / "bench_node.py"), "--republisher"],
                           log=logs / "bare.log")
        topic, pose = "/bare_republisher/out", True
    elif base == "sink":
        params = {k: v for k, v in outputs.items() if k.removeprefix("output.").removesuffix("_every")
                  in ("odometry", "covariance", "typed", "markers")}
        node = NodeProcess("estimator", ros_args(params=params) if params else [],
                           cmd=[sys.executable, str(REPO / "bench" / "sink_node.py"), str(sys_path)],
                           env=env, log=log)
        topic, pose = "/estimator/state", False
        if listen:
            optional = optional_outputs(so.load_system(sys_path))
    else:
        params = dict(sched, system=str(sys_path), gain_table=tables[base.removeprefix("main:")], e0=1e3, **outputs)
        code = (f"import sys; sys.path.insert(0, {str(repo)!r}); import runpy; "
                "runpy.run_module('switchobs_ros.estimator', run_name='__main__')")
        cmd = ([sys.executable, str(REPO / "bench" / "profile_node.py"), str(profile)] if profile
               else [sys.executable, "-c", code])
        env["SWITCHOBS_PROFILE_REPO"] = str(repo)
        node = NodeProcess("estimator", ros_args(params=params), cmd=cmd, env=env, log=log)
        topic, pose = "/estimator/state", False
        if listen:
            optional = optional_outputs(so.load_system(sys_path))
    rec = Receiver(topic, pose, optional)
    try:
        end = time.monotonic() + 180
        while (rec.count_publishers(topic) == 0 or any(rec.count_publishers(t) == 0 for t, _ in optional)) \
                and time.monotonic() < end:
            rclpy.spin_once(rec, timeout_sec=0.1)
        x0 = np.random.default_rng(1).uniform(-1.0, 1.0, 4 * (m + 1))
        cam = NodeProcess("camera_sim", ros_args(params=dict(sched, system=str(sys_path), rate=rate,
                                                             duration=seconds, wait_for_subscribers=1,
                                                             wait_for_truth_subscribers=1,
                                                             initial_state=list(map(float, x0)))),
                          log=logs / f"camera_{kind.replace(':', '_')}.log")
        cpu0 = th0 = sampler = None
        while cam.alive():
            rclpy.spin_once(rec, timeout_sec=0.05)
            if cpu0 is None and rec.truth:
                cpu0 = cpu_seconds(node.pid)
                th0 = thread_cpu(node.pid) if threads else None
                if spy_dir is not None:
                    sampler = spy(node.pid, seconds, spy_dir / f"{tag}.txt")
        t_end = time.monotonic() + 2.0
        while time.monotonic() < t_end:
            rclpy.spin_once(rec, timeout_sec=0.05)
        cpu1 = cpu_seconds(node.pid)
        th1 = thread_cpu(node.pid) if threads else None
        if sampler is not None:
            sampler.wait(timeout=60)
    finally:
        node.stop()
        rec.destroy_node()
    sent = sorted(rec.truth)
    answered = [s for s in sent if s in rec.answers]
    lat = np.array([(rec.answers[s] - s) * 1e-6 for s in answered])
    return {"node": kind, "sent": len(sent), "answered": len(answered),
            "p50": float(np.median(lat)) if lat.size else float("nan"),
            "p99": float(np.percentile(lat, 99)) if lat.size else float("nan"),
            "cpu_ms": 1e3 * (cpu1 - (cpu0 or cpu1)) / max(len(answered), 1), "counts": dict(rec.counts),
            "threads": ({k: [v - th0.get(k, [0.0] * 3)[i] for i, v in enumerate(row)] for k, row in th1.items()}
                        if th0 is not None and th1 is not None else None)}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--agents", type=int, default=32)
    ap.add_argument("--seconds", type=float, default=60.0)
    ap.add_argument("--rate", type=float, default=50.0)
    ap.add_argument("--nodes", default="bare,kalman,lmi",
                    help="comma-separated: bare, sink, kalman, lmi, main:kalman, main:lmi, each with an optional "
                         "@rclpy (rclpy's SingleThreadedExecutor instead of switchobs_ros.executor's); a node may "
                         "repeat (interleaved rounds)")
    ap.add_argument("--listen", action="store_true",
                    help="subscribe to every optional output of the estimator (envelope, covariance, typed, "
                         "markers, one odometry per body), so that each is built and published")
    ap.add_argument("--every", default="", metavar="K=V,...",
                    help="the estimator's output.<K>_every, e.g. odometry=5,covariance=5,typed=5")
    ap.add_argument("--profile", type=Path, default=None, metavar="DIR",
                    help="run each estimator under cProfile (bench/profile_node.py), stats in DIR/<node>-<i>.prof")
    ap.add_argument("--main-repo", type=Path, default=Path("/work/main"),
                    help="the checkout whose estimator a node main:<kind> runs (before/after in one run)")
    ap.add_argument("--threads", action="store_true",
                    help="the node's CPU per answer by thread name (user, system) and minor page faults per answer")
    ap.add_argument("--spy", type=Path, default=None, metavar="DIR",
                    help="sample each node with py-spy --native (PY_SPY: its path), raw stacks in DIR/<node>-<i>.txt")
    ap.add_argument("--domain", type=int, default=None, help="ROS_DOMAIN_ID (default: claim a free one)")
    a = ap.parse_args(argv)
    every = {k: int(v) for k, v in (kv.split("=") for kv in a.every.split(",") if kv)}
    info = machine_info()
    lease = claim_domain() if a.domain is None else None
    os.environ["ROS_DOMAIN_ID"] = str(lease.domain_id if lease else a.domain)
    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    kinds = a.nodes.split(",")
    with tempfile.TemporaryDirectory(prefix="bench_live_scale_") as tmp:
        d = Path(tmp)
        sys_path = d / f"agents{a.agents}.yaml"
        sys_path.write_text(yaml.safe_dump({"scenario": "camera_agents", "agents": a.agents}))
        system = so.load_system(sys_path)
        cycle = so.Cycle([1.0] * a.agents)
        tables = {}
        bases = {k.partition("@")[0].removeprefix("main:") for k in kinds}
        if "kalman" in bases:
            tables["kalman"] = str(so.kalman_table(system, [so.design_kalman(system, cycle, a.rate)]).save(d / "k.npz"))
        if "lmi" in bases:
            tables["lmi"] = str(so.design_table(system, cycles=[cycle]).save(d / "lmi.json"))
        rclpy.init()
        try:
            for d_ in (a.profile, a.spy):
                if d_:
                    d_.mkdir(parents=True, exist_ok=True)
            rows = [run_node(k, a.agents, a.seconds, a.rate, sys_path, tables, d, a.listen, every,
                             a.profile / f"{k.replace(':', '_')}-{i}.prof" if a.profile and k != "bare" else None,
                             a.main_repo, a.threads, a.spy, f"{k.replace(':', '_').replace('@', '_')}-{i}")
                    for i, k in enumerate(kinds)]
        finally:
            rclpy.try_shutdown()
            if lease:
                lease.release()
    print(f"Machine: {info['cpu']}, {info['nproc']} cores, Python {info['python']}; commit {info['commit']}; "
          f"load average {info['load'][0]:.1f} before ({info['date']}).")
    extra = (" --listen" if a.listen else "") + (f" --every {a.every}" if a.every else "")
    print(f"Command: `OPENBLAS_NUM_THREADS=1 python bench/bench_live_scale.py --agents {a.agents} "
          f"--seconds {a.seconds:g} --rate {a.rate:g} --nodes {a.nodes}{extra}`\n")
    bare = next((r for r in rows if r["node"] == "bare"), None)
    print("| node | ticks sent | answered | fraction | latency p50 | p99 | CPU per answer | p99 / bare | CPU / bare |")
    print("|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        rp = f"{r['p99'] / bare['p99']:.2f}x" if bare else "-"
        rc = f"{r['cpu_ms'] / bare['cpu_ms']:.1f}x" if bare else "-"
        print(f"| {r['node']} | {r['sent']} | {r['answered']} | {r['answered'] / max(r['sent'], 1):.4f} "
              f"| {r['p50']:.1f} ms | {r['p99']:.1f} ms | {r['cpu_ms']:.2f} ms | {rp} | {rc} |")
    kinds_seen = list(dict.fromkeys(r["node"] for r in rows))
    if len(kinds_seen) < len(rows):        # rounds: medians per node, ratios against bare's median
        med = {k: {q: float(np.median([r[q] for r in rows if r["node"] == k])) for q in ("p50", "p99", "cpu_ms")}
               for k in kinds_seen}
        base = med.get("bare")
        print("\nMedians over the rounds:\n")
        print("| node | rounds | answered (all) | latency p50 | p99 | CPU per answer | p99 / bare | CPU / bare |")
        print("|---|---|---|---|---|---|---|---|")
        for k in kinds_seen:
            rs = [r for r in rows if r["node"] == k]
            m = med[k]
            print(f"| {k} | {len(rs)} | {sum(r['answered'] for r in rs)}/{sum(r['sent'] for r in rs)} "
                  f"| {m['p50']:.1f} ms | {m['p99']:.1f} ms | {m['cpu_ms']:.2f} ms "
                  f"| {m['p99'] / base['p99']:.2f}x | {m['cpu_ms'] / base['cpu_ms']:.1f}x |" if base else "| - | - |")
    for r in rows:
        if r["threads"]:
            k = max(r["answered"], 1)
            print(f"\n{r['node']}: CPU per answer by thread (user + system, ms), minor faults per answer:")
            for name, (u, st, flt) in sorted(r["threads"].items(), key=lambda kv: -(kv[1][0] + kv[1][1])):
                if u + st > 0 or flt > 0:
                    print(f"  {name:16s} {1e3 * (u + st) / k:6.3f} ({1e3 * u / k:.3f} + {1e3 * st / k:.3f})"
                          f"  faults {flt / k:.1f}")
    for r in rows:
        if r["counts"]:
            c = r["counts"]
            odom = sum(v for t, v in c.items() if t.endswith("/odom"))
            rest = ", ".join(f"{t.rsplit('/', 1)[1]} {v}" for t, v in c.items() if not t.endswith("/odom"))
            print(f"\n{r['node']}: messages received on the optional outputs: {rest}, odometry {odom} "
                  f"({sum(t.endswith('/odom') for t in c)} bodies)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
