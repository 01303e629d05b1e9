#!/usr/bin/env python
"""The estimator node live at scale: 32 agents (n = 132) at 50 Hz over DDS against a bare rclpy
republisher, side by side in one run.

    python bench/bench_live_scale.py                       # 32 agents, 50 Hz, 60 s per node
    python bench/bench_live_scale.py --agents 8 --seconds 20 --nodes kalman,bare

Processes per run, one role each: camera_sim (the built-in ``camera_agents`` model with M agents,
every h_i = 1 s, stamping each tick on its grid) as the sender; the node under test: the
estimator with the model's Kalman table (``kalman``) or LMI table (``lmi``), all outputs at their
defaults, or the ceiling (``bare``), a bare rclpy node that republishes every target pose
(``bench/bench_node.py --republisher``), or the messaging floor (``sink``, ``bench/sink_node.py``:
the estimator's subscriptions and outputs, no math); a node ``<kind>@rclpy`` spins rclpy's
SingleThreadedExecutor, ``<kind>@events`` rclpy's EventsExecutor, otherwise
``switchobs_ros.executor.KeptWaitSetExecutor`` (``SWITCHOBS_EXECUTOR``); this process as the
receiver of each answer (``/estimator/state``, or the republisher's ``~/out``) and of each truth
message (one per tick: what was sent); and, with ``--listen`` (or a node ``<kind>+listen``), a
listener that subscribes to every optional output of the estimator so that each is built and
published, and counts them: ``bench/output_counter.py`` in a process of its own (``--counter
process``, the default) or raw subscriptions in the receiver (``--counter inline``), both taken
raw by ``KeptWaitSetExecutor``. A node ``<kind>+dds`` runs with the Fast DDS profile
``--node-dds-profile`` (default ``bench/fastdds_shm_segment.xml``: an 8 MiB shared-memory segment).

Latency = the answer's arrival at the receiver's middleware (``MessageInfo.received_timestamp``,
Fast DDS's reception time, on the system clock: ``bench/_receipt.py``) - the tick's stamp (the
same clock): the node and the transport, not the receiver's own queue. The arrival in the
receiver's Python callback is a second column (what this benchmark measured before). Reported per
node: ticks camera_sim sent and the ticks it skipped (the stamps missing from its grid: a tick is
skipped when its timer's wake-ups straddle the grid of stamps), answers, the fraction answered,
latency p50 and p99, the node process's CPU time per answer (user + system, from ``/proc``, from
the first tick to the last answer), camera_sim's own lateness (each truth message's DDS reception
- its stamp: published after the tick's poses), and ratios against ``bare`` in the same run; the
receiver also witnesses ``/target/pose``, so that the latency *from publication* (the answer's
reception - camera_sim's publication of the tick's target pose) leaves camera_sim's lateness out,
and splits it: at the node, the answer's delivery, the receiver's own queue. ``--threads`` adds the
node's CPU per answer by thread name (the Python thread, Fast DDS's ``dds.*`` threads) and its
minor page faults; ``--spy DIR`` samples each node with py-spy ``--native`` (``PY_SPY``: its
path; it pauses the process at each sample, so the run is slower).

A script, not a test: nothing is asserted.
"""

from __future__ import annotations

import argparse
import json
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
from _receipt import RECEIVE, WITNESS, Receipts, labelled_stamp, pose_stamp  # noqa: E402
from geometry_msgs.msg import PoseStamped  # noqa: E402
from output_counter import counting, optional_outputs  # noqa: E402
from rclpy.node import Node  # noqa: E402
from std_msgs.msg import Float64MultiArray  # noqa: E402

import switchobs_core as so  # noqa: E402
from switchobs_ros.executor import KeptWaitSetExecutor  # noqa: E402
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
    """Keeps every answer, every truth message and, as a witness, every target pose raw, with its
    DDS reception, source and Python arrival times (``bench/_receipt.py``; decoded after the run);
    with ``optional`` topics, also counts the messages on each (taken raw: not deserialised here)."""

    def __init__(self, answer_topic: str, pose: bool, optional: tuple[tuple[str, type], ...] = ()):
        super().__init__("bench_live_receiver")
        self.answers = Receipts()
        self.truth = Receipts()
        self.create_subscription(PoseStamped if pose else Float64MultiArray, answer_topic, self.answers, RECEIVE,
                                 raw=True)
        self.create_subscription(Float64MultiArray, "/sim/truth", self.truth, RECEIVE, raw=True)
        self.poses = Receipts()
        self.create_subscription(PoseStamped, "/target/pose", self.poses, WITNESS, raw=True)
        self.counts = counting(self, optional, RECEIVE)


def percentiles(values) -> tuple[float, float]:
    """(p50, p99) of ``values``, NaN for none."""
    v = np.asarray(values, dtype=float)
    return (float(np.median(v)), float(np.percentile(v, 99))) if v.size else (float("nan"), float("nan"))


def parse_kind(kind: str) -> tuple[str, str, bool | None, bool]:
    """``base[@executor][+listen|+quiet][+dds][+once][+phase]`` -> (base, executor, listened: None = as
    ``--listen``, the node under ``--node-dds-profile``); ``+once`` (read by :func:`run_node`) sets the
    estimator's ``switch_horizon`` to 1, ``+phase`` its ``bound`` to ``phase`` (the per-phase scalar bound)."""
    name, *mods = kind.split("+")
    if not set(mods) <= {"listen", "quiet", "dds", "once", "phase"} or {"listen", "quiet"} <= set(mods):
        raise SystemExit(f"node {kind!r}: the suffixes are +listen or +quiet, +dds, +once and +phase")
    base, _, executor = name.partition("@")
    return base, executor, "listen" in mods if {"listen", "quiet"} & set(mods) else None, "dds" in mods


def run_node(kind: str, m: int, seconds: float, rate: float, sys_path: Path, tables: dict, logs: Path,
             listen: bool = False, every: dict | None = None, profile: Path | None = None,
             main_repo: Path | None = None, threads: bool = False, spy_dir: Path | None = None,
             tag: str = "", counter: str = "process", dds_profile: Path | None = None,
             phases: Path | None = None, split: float = 0.0) -> dict:
    """One node under test: ``listen`` subscribes to every optional output of the estimator (a
    ``+listen`` / ``+quiet`` suffix of ``kind`` overrides it), counted by ``bench/output_counter.py``
    (``counter`` ``process``) or by this process (``inline``); ``every`` sets its
    ``output.*_every``, ``profile`` runs it under cProfile (bench/profile_node.py); a ``kind``
    ``main:kalman`` runs the estimator of the checkout ``main_repo`` instead of this one;
    ``threads`` records the node's CPU per thread name, ``spy_dir`` samples it with py-spy; a
    ``+dds`` suffix runs the node (only) with the Fast DDS profile ``dds_profile``; ``+once`` runs the
    estimator with ``switch_horizon`` 1 (every sample of a residence answered at once); ``phases``
    runs it under bench/phase_node.py (its CPU by phase, JSON in that file); ``split`` (s) also takes the
    node's CPU (and per thread) that long after the first tick, to report both windows apart."""
    base, executor, listened, own_profile = parse_kind(kind)
    listen = listen if listened is None else listened
    repo = main_repo if base.startswith("main:") else REPO
    env = dict(os.environ, SWITCHOBS_EXECUTOR=executor or "kept")
    if own_profile:
        env["FASTRTPS_DEFAULT_PROFILES_FILE"] = str(dds_profile)
    stem = tag or kind.replace(":", "_").replace("@", "_").replace("+", "_")
    log = logs / f"{stem}.log"
    sched = {"schedule.mode": "periodic", "schedule.h": [1.0] * m}
    optional = ()
    outputs = {f"output.{k}_every": v for k, v in (every or {}).items()}
    if base == "bare":
        node = NodeProcess("bare", cmd=[sys.executable, str(REPO / "bench" / "bench_node.py"), "--republisher"],
                           env=env, log=log)
        topic, pose = "/bare_republisher/out", True
    elif base == "sink":
        params = {k: v for k, v in outputs.items() if k.removeprefix("output.").removesuffix("_every")
                  in ("odometry", "covariance", "typed", "markers")}
        node = NodeProcess("estimator", ros_args(params=params) if params else [],
                           cmd=[sys.executable, str(REPO / "bench" / "sink_node.py"), str(sys_path)],
                           env=env, log=log)
        topic, pose = "/estimator/state", False
    else:
        params = dict(sched, system=str(sys_path), gain_table=tables[base.removeprefix("main:")], e0=1e3, **outputs)
        if "once" in kind.split("+")[1:]:
            params["switch_horizon"] = 1.0
        if "phase" in kind.split("+")[1:]:
            params["bound"] = "phase"
        code = (f"import sys; sys.path.insert(0, {str(repo)!r}); import runpy; "
                "runpy.run_module('switchobs_ros.estimator', run_name='__main__')")
        cmd = ([sys.executable, str(REPO / "bench" / "profile_node.py"), str(profile)] if profile
               else [sys.executable, str(REPO / "bench" / "phase_node.py"), str(phases)] if phases
               else [sys.executable, "-c", code])
        env["SWITCHOBS_PROFILE_REPO"] = str(repo)
        node = NodeProcess("estimator", ros_args(params=params), cmd=cmd, env=env, log=log)
        topic, pose = "/estimator/state", False
    if listen and base != "bare":
        optional = optional_outputs(so.load_system(sys_path))
    counts_file = logs / f"{stem}.counts.json"
    listener = (NodeProcess("output_counter", cmd=[sys.executable, str(REPO / "bench" / "output_counter.py"),
                                                   str(sys_path), str(counts_file)], log=logs / f"{stem}.counter.log")
                if optional and counter == "process" else None)
    rec = Receiver(topic, pose, optional if counter == "inline" else ())
    ex = KeptWaitSetExecutor()
    ex.add_node(rec)
    try:
        end = time.monotonic() + 180
        while (rec.count_publishers(topic) == 0 or any(rec.count_publishers(t) == 0 or rec.count_subscribers(t) == 0
                                                       for t, _ in optional)) and time.monotonic() < end:
            ex.spin_once(timeout_sec=0.1)
        x0 = np.random.default_rng(1).uniform(-1.0, 1.0, 4 * (m + 1))
        # camera_sim starts when the node and this witness subscribe to the target pose
        cam = NodeProcess("camera_sim", ros_args(params=dict(sched, system=str(sys_path), rate=rate,
                                                             duration=seconds, wait_for_subscribers=2,
                                                             wait_for_truth_subscribers=1,
                                                             initial_state=list(map(float, x0)))),
                          log=logs / f"camera_{stem}.log")
        cpu0 = th0 = sampler = mid = None
        t_first = 0.0
        while cam.alive():
            ex.spin_once(timeout_sec=0.05)
            if cpu0 is not None and split and mid is None and time.monotonic() >= t_first + split:
                mid = (cpu_seconds(node.pid), thread_cpu(node.pid) if threads else None, len(rec.answers))
            if cpu0 is None and len(rec.truth):
                cpu0 = cpu_seconds(node.pid)
                th0 = thread_cpu(node.pid) if threads else None
                t_first = time.monotonic()
                if spy_dir is not None:
                    sampler = spy(node.pid, seconds, spy_dir / f"{tag}.txt")
        t_end = time.monotonic() + 2.0
        while time.monotonic() < t_end:
            ex.spin_once(timeout_sec=0.05)
        cpu1 = cpu_seconds(node.pid)
        th1 = thread_cpu(node.pid) if threads else None
        if sampler is not None:
            sampler.wait(timeout=60)
    finally:
        node.stop()
        counts = dict(rec.counts)
        if listener is not None:
            listener.stop(timeout=30)
            counts = json.loads(counts_file.read_text()) if counts_file.exists() else {}
        ex.remove_node(rec)
        rec.destroy_node()
        ex.shutdown()
    truth = rec.truth.times(labelled_stamp)
    answers = rec.answers.times(pose_stamp if pose else labelled_stamp)
    sent = sorted(truth)
    answered = [s for s in sent if s in answers]
    p50, p99 = percentiles([(answers[s][0] - s) * 1e-6 for s in answered])
    py50, py99 = percentiles([(answers[s][2] - s) * 1e-6 for s in answered])
    cam50, cam99 = percentiles([(truth[s][0] - s) * 1e-6 for s in sent])
    poses = rec.poses.times(pose_stamp)
    pub50, pub99 = percentiles([(answers[s][0] - poses[s][1]) * 1e-6 for s in answered if s in poses])
    split = {"node": percentiles([(answers[s][1] - poses[s][1]) * 1e-6 for s in answered if s in poses]),
             "delivery": percentiles([(answers[s][0] - answers[s][1]) * 1e-6 for s in answered]),
             "queue": percentiles([(answers[s][2] - answers[s][0]) * 1e-6 for s in answered])}
    return {"node": kind, "sent": len(sent), "skipped": round(seconds * rate) + 1 - len(sent),
            "answered": len(answered), "p50": p50, "p99": p99, "py_p50": py50, "py_p99": py99,
            "pub_p50": pub50, "pub_p99": pub99, "split": split,
            "cam_p50": cam50, "cam_p99": cam99,
            "cpu_ms": 1e3 * (cpu1 - (cpu0 or cpu1)) / max(len(answered), 1), "counts": counts,
            "windows": None if mid is None else _windows(cpu0, th0, mid, cpu1, th1, len(rec.answers)),
            "threads": ({k: [v - th0.get(k, [0.0] * 3)[i] for i, v in enumerate(row)] for k, row in th1.items()}
                        if th0 is not None and th1 is not None else None)}


def _windows(cpu0: float, th0: dict | None, mid: tuple, cpu1: float, th1: dict | None, n1: int) -> list[dict]:
    """CPU per answer before and after ``mid`` (its process CPU, thread CPU and answers so far): per
    window the answers, ms per answer and, with threads, the Python thread's user, system (ms per
    answer) and minor faults per answer."""
    out = []
    for (c_a, t_a, n_a), (c_b, t_b, n_b) in (((cpu0, th0, 0), mid), (mid, (cpu1, th1, n1))):
        k = max(n_b - n_a, 1)
        row = {"answers": n_b - n_a, "cpu_ms": 1e3 * (c_b - c_a) / k}
        if t_a is not None and t_b is not None and "python" in t_b:
            a = t_a.get("python", [0.0] * 3)
            row["python"] = [1e3 * (t_b["python"][0] - a[0]) / k, 1e3 * (t_b["python"][1] - a[1]) / k,
                             (t_b["python"][2] - a[2]) / k]
        out.append(row)
    return out


def ratios(r: dict, bare: dict | None, latency: str = "") -> str:
    """Table cells: p50 and p99 (``latency``: the prefix of another latency's keys) of ``r`` over
    ``bare``'s, and CPU per answer unless ``latency``."""
    if not bare:
        return "- | -" + ("" if latency else " | -")
    cells = f"{r[latency + 'p50'] / bare[latency + 'p50']:.2f}x | {r[latency + 'p99'] / bare[latency + 'p99']:.2f}x"
    return cells if latency else f"{cells} | {r['cpu_ms'] / bare['cpu_ms']:.1f}x"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--agents", type=int, default=32)
    ap.add_argument("--seconds", type=float, default=60.0)
    ap.add_argument("--rate", type=float, default=50.0)
    ap.add_argument("--nodes", default="bare,kalman,lmi",
                    help="comma-separated: bare, sink, kalman, lmi, main:kalman, main:lmi, each with an optional "
                         "@rclpy (rclpy's SingleThreadedExecutor instead of switchobs_ros.executor's) and an optional "
                         "+listen or +quiet (this node's outputs listened or not, whatever --listen says), +dds (under "
                         "--node-dds-profile), +once (the estimator's switch_horizon 1) and +phase (its bound: "
                         "phase); a node may repeat (interleaved rounds)")
    ap.add_argument("--listen", action="store_true",
                    help="subscribe to every optional output of the estimator (envelope, covariance, typed, "
                         "markers, one odometry per body), so that each is built and published")
    ap.add_argument("--counter", choices=("process", "inline"), default="process",
                    help="who takes the optional outputs: bench/output_counter.py in a process of its own, or raw "
                         "subscriptions in the receiver")
    ap.add_argument("--node-dds-profile", type=Path, default=REPO / "bench" / "fastdds_shm_segment.xml",
                    help="the Fast DDS profile (FASTRTPS_DEFAULT_PROFILES_FILE) of the nodes written <kind>+dds")
    ap.add_argument("--every", default="", metavar="K=V,...",
                    help="the estimator's output.<K>_every, e.g. odometry=5,covariance=5,typed=5")
    ap.add_argument("--profile", type=Path, default=None, metavar="DIR",
                    help="run each estimator under cProfile (bench/profile_node.py), stats in DIR/<node>-<i>.prof")
    ap.add_argument("--phases", type=Path, default=None, metavar="DIR",
                    help="run each estimator under bench/phase_node.py: its thread's CPU by phase "
                         "(bench/phases.py), JSON in DIR/<node>-<i>.json and a table at the end")
    ap.add_argument("--main-repo", type=Path, default=Path("/work/main"),
                    help="the checkout whose estimator a node main:<kind> runs (before/after in one run)")
    ap.add_argument("--threads", action="store_true",
                    help="the node's CPU per answer by thread name (user, system) and minor page faults per answer")
    ap.add_argument("--spy", type=Path, default=None, metavar="DIR",
                    help="sample each node with py-spy --native (PY_SPY: its path), raw stacks in DIR/<node>-<i>.txt")
    ap.add_argument("--domain", type=int, default=None, help="ROS_DOMAIN_ID (default: claim a free one)")
    ap.add_argument("--split", type=float, default=0.0, metavar="S",
                    help="also report each node's CPU per answer in the first S seconds from the first tick and "
                         "after (e.g. 32: one period of the 32-agent schedule, the Kalman table's first visits)")
    ap.add_argument("--table-version", type=int, default=0, metavar="V",
                    help="write the Kalman table in container version V (4: what a --main-repo checkout "
                         "before version 5 reads; default: the current version)")
    a = ap.parse_args(argv)
    every = {k: int(v) for k, v in (kv.split("=") for kv in a.every.split(",") if kv)}
    kinds = a.nodes.split(",")
    bases = {parse_kind(k)[0].removeprefix("main:") for k in kinds}
    info = machine_info()
    lease = claim_domain() if a.domain is None else None
    os.environ["ROS_DOMAIN_ID"] = str(lease.domain_id if lease else a.domain)
    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    with tempfile.TemporaryDirectory(prefix="bench_live_scale_") as tmp:
        d = Path(tmp)
        sys_path = d / f"agents{a.agents}.yaml"
        sys_path.write_text(yaml.safe_dump({"scenario": "camera_agents", "agents": a.agents}))
        system = so.load_system(sys_path)
        cycle = so.Cycle([1.0] * a.agents)
        tables = {}
        if "kalman" in bases:
            kt = so.kalman_table(system, [so.design_kalman(system, cycle, a.rate)])
            if a.table_version:             # what a --main-repo checkout of an older container reads
                from switchobs_core.table.container import encode
                from switchobs_core.table.io import table_payload
                with open(d / "k.npz", "wb") as fh:
                    encode(table_payload(kt), fh, version=a.table_version)
                tables["kalman"] = str(d / "k.npz")
            else:
                tables["kalman"] = str(kt.save(d / "k.npz"))
        if "lmi" in bases:
            tables["lmi"] = str(so.design_table(system, cycles=[cycle]).save(d / "lmi.json"))
        rclpy.init()
        try:
            for d_ in (a.profile, a.spy, a.phases):
                if d_:
                    d_.mkdir(parents=True, exist_ok=True)
            rows = []
            for i, k in enumerate(kinds):
                tag = f"{k.replace(':', '_').replace('@', '_').replace('+', '_')}-{i}"
                rows.append(run_node(k, a.agents, a.seconds, a.rate, sys_path, tables, d, a.listen, every,
                                     a.profile / f"{tag}.prof" if a.profile and parse_kind(k)[0] != "bare" else None,
                                     a.main_repo, a.threads, a.spy, tag, a.counter, a.node_dds_profile,
                                     a.phases / f"{tag}.json" if a.phases and parse_kind(k)[0] not in ("bare", "sink")
                                     else None, a.split))
                r = rows[-1]
                sys.stderr.write(f"{k}: {r['answered']}/{r['sent']} ({r['skipped']} skipped), p50 {r['p50']:.1f} ms, "
                                 f"p99 {r['p99']:.1f} ms (Python arrival {r['py_p99']:.1f} ms), "
                                 f"CPU {r['cpu_ms']:.2f} ms per answer\n")
        finally:
            rclpy.try_shutdown()
            if lease:
                lease.release()
    print(f"Machine: {info['cpu']}, {info['nproc']} cores, Python {info['python']}; commit {info['commit']}; "
          f"load average {info['load'][0]:.1f} before, {os.getloadavg()[0]:.1f} after ({info['date']}).")
    extra = (" --listen" if a.listen else "") + (f" --every {a.every}" if a.every else "") \
        + (f" --counter {a.counter}" if a.counter != "process" else "") \
        + (f" --node-dds-profile {a.node_dds_profile}" if any(parse_kind(k)[3] for k in kinds) else "")
    print(f"Command: `OPENBLAS_NUM_THREADS=1 python bench/bench_live_scale.py --agents {a.agents} "
          f"--seconds {a.seconds:g} --rate {a.rate:g} --nodes {a.nodes}{extra}`\n")
    print("Latency: the answer's DDS reception at the receiver - the tick's stamp; \"Python\": its arrival in the "
          "receiver's callback instead; \"from publication\": the answer's DDS reception - camera_sim's publication "
          "of the tick's target pose (its writer's source time: camera_sim's lateness taken out). Camera late: "
          "camera_sim's truth message's DDS reception - its stamp.\n")
    bare = next((r for r in rows if parse_kind(r["node"])[0] == "bare"), None)
    print("| node | ticks sent | skipped | answered | fraction | latency p50 | p99 | p99 (Python) | CPU per answer "
          "| p50 / bare | p99 / bare | CPU / bare | camera late p50 / p99 | from publication p50 / p99 "
          "| p50 / bare | p99 / bare |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['node']} | {r['sent']} | {r['skipped']} | {r['answered']} "
              f"| {r['answered'] / max(r['sent'], 1):.4f} | {r['p50']:.1f} ms | {r['p99']:.1f} ms "
              f"| {r['py_p99']:.1f} ms | {r['cpu_ms']:.2f} ms | {ratios(r, bare)} "
              f"| {r['cam_p50']:.1f} / {r['cam_p99']:.1f} ms | {r['pub_p50']:.1f} / {r['pub_p99']:.1f} ms "
              f"| {ratios(r, bare, 'pub_')} |")
    kinds_seen = list(dict.fromkeys(r["node"] for r in rows))
    if len(kinds_seen) < len(rows):        # rounds: medians per node, ratios against bare's median
        qs = ("p50", "p99", "py_p99", "cpu_ms", "pub_p50", "pub_p99")
        med = {k: {q: float(np.median([r[q] for r in rows if r["node"] == k])) for q in qs} for k in kinds_seen}
        base = next((med[k] for k in kinds_seen if parse_kind(k)[0] == "bare"), None)
        print("\nMedians over the rounds:\n")
        print("| node | rounds | answered (all) | skipped (all) | latency p50 | p99 | p99 (Python) | CPU per answer "
              "| p50 / bare | p99 / bare | CPU / bare | from publication p50 / p99 | p50 / bare | p99 / bare |")
        print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
        for k in kinds_seen:
            rs = [r for r in rows if r["node"] == k]
            m = med[k]
            print(f"| {k} | {len(rs)} | {sum(r['answered'] for r in rs)}/{sum(r['sent'] for r in rs)} "
                  f"| {sum(r['skipped'] for r in rs)} | {m['p50']:.1f} ms | {m['p99']:.1f} ms | {m['py_p99']:.1f} ms "
                  f"| {m['cpu_ms']:.2f} ms | {ratios(m, base)} | {m['pub_p50']:.1f} / {m['pub_p99']:.1f} ms "
                  f"| {ratios(m, base, 'pub_')} |")
    print("\nWhere the time from publication goes, p50 / p99 (ms): at the node (its answer's publication - the "
          "target pose's), the answer's delivery (its DDS reception at the receiver - its publication), the "
          "receiver's own queue (Python arrival - DDS reception):\n")
    print("| node | at the node | delivery | receiver's queue |")
    print("|---|---|---|---|")
    for r in rows:
        print(f"| {r['node']} | " + " | ".join(f"{r['split'][k][0]:.1f} / {r['split'][k][1]:.1f}"
                                           for k in ("node", "delivery", "queue")) + " |")
    if a.split:
        print(f"\nCPU per answer before and after {a.split:g} s from the first tick (ms; with --threads the Python "
              "thread's user + system and its minor faults per answer):\n")
        print("| node | answers before | CPU before | Python thread before | answers after | CPU after "
              "| Python thread after |")
        print("|---|---|---|---|---|---|---|")
        for r in rows:
            if r["windows"]:
                cells = [f"{w['answers']} | {w['cpu_ms']:.2f} | " + (
                    f"{w['python'][0]:.3f} + {w['python'][1]:.3f}, {w['python'][2]:.1f} faults" if "python" in w
                    else "-") for w in r["windows"]]
                print(f"| {r['node']} | " + " | ".join(cells) + " |")
    for r in rows:
        if r["threads"]:
            k = max(r["answered"], 1)
            print(f"\n{r['node']}: CPU per answer by thread (user + system, ms), minor faults per answer:")
            for name, (u, st, flt) in sorted(r["threads"].items(), key=lambda kv: -(kv[1][0] + kv[1][1])):
                if u + st > 0 or flt > 0:
                    print(f"  {name:16s} {1e3 * (u + st) / k:6.3f} ({1e3 * u / k:.3f} + {1e3 * st / k:.3f})"
                          f"  faults {flt / k:.1f}")
    if a.phases:
        import phases as ph
        got = {p.stem: json.loads(p.read_text()) for p in sorted(a.phases.glob("*.json"))}
        if got:
            print("\nThe node's spinning thread by phase (bench/phases.py: own CPU per answer, ms):\n")
            print(ph.table(got))
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
