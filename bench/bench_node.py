"""Benchmark of the estimator node over DDS (not a test): latency and throughput against a bare
rclpy republisher, measured by processes that do nothing else.

``python bench/bench_node.py [--seconds 5] [--rates 100,250,500,1000] [--configs default,events]
[--soak 60] [--figure bench/figures/node_latency.png]``

Four processes per run, one role each, so that the measurement is the node's and not the driver's:

* the node under test: the estimator (one configuration of it), or the ceiling, a bare rclpy node
  that republishes every target PoseStamped (same QoS: sensor-data subscriptions, reliable output);
* a *sender* that publishes camera/pose + target/pose pairs at the rate, stamped with the send
  time; it paces with ``time.sleep`` only (no spinning: the previous driver spun its last
  millisecond before each send in the process that also received the answers, and inflated the
  latency it measured);
* a *receiver* that subscribes to the answers and records their arrival time, and, as a
  *witness*, also subscribes the sender's ``target/pose`` (the node's QoS): a late answer whose
  measurement also reached the witness late was delayed before any node (sender, middleware,
  machine), one whose measurement reached it in time was delayed at the node;
* this process, which starts them in turn (estimator configurations and the republisher
  alternate at each rate, in one run) and reads the two files.

Latency = the answer's arrival at the receiver's middleware (``MessageInfo.received_timestamp``,
``bench/_receipt.py``) - the measurement's header stamp (both this machine's system clock); the
arrival in the receiver's Python callback is a second p50 column. A rate is
"answered in full" when every measurement gets its answer. ``--soak S`` runs the estimator at
500 Hz for S seconds and reports the largest latency.

Configurations (``--configs``, ``--soak-config``): ``on-change-uint8`` and ``on-change-stamped``
(the sender switches channels by the paper's cycle and publishes the channel only on a change, as
``UInt8`` or as the stamped ``ActiveChannel``; otherwise it publishes channel 1 once),
``on-change-stamped-once`` (the latter with the estimator's ``switch_horizon`` 1),
``every-tick-stamped`` (camera_sim's pattern: the stamped channel every tick, after the poses but on
a switching tick) and ``every-tick-stamped-first`` (the same messages, the channel first every tick), the
estimator's ``default``, ``no-gc-freeze``,
``state-only``, ``lean-loop``, ``traced``, ``rt`` (its process under ``chrt -f 40``), ``udp``
(``FASTDDS_BUILTIN_TRANSPORTS=UDPv4``), and ``bare`` (the republisher) for soaks. ``--load K``
runs K busy loops throughout: a busy machine.

Writes a Markdown section to stdout (recorded in bench/RESULTS.md) and, with ``--figure``, a
latency histogram per rate.
"""

from __future__ import annotations

import argparse
import os
import platform
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

#: Estimator configurations compared (parameters on top of the gain table).
CONFIGS = {
    "default": {},
    "no-gc-freeze": {"gc_freeze": False},
    "state-only": {"output.envelope_every": 0, "output.odometry_every": 0, "output.covariance_every": 0},
    "lean-loop": {"_lean": True},
    "traced": {"_trace": True},
    "rt": {"_chrt": 40},        # the node's process under SCHED_FIFO 40 (`chrt -f 40`, every thread)
    "udp": {"_env": {"FASTDDS_BUILTIN_TRANSPORTS": "UDPv4"}},       # no shared-memory transport
    # the sender switches by the paper's cycle (2 s, 0.6) and publishes the channel only when it
    # changes, before that tick's poses (camera_sim's order): std_msgs/UInt8, or the stamped
    # switchobs_msgs/ActiveChannel (its switching instant: the first tick on the channel)
    "on-change-uint8": {"_channel": "uint8"},
    "on-change-stamped": {"_channel": "stamped"},
    # the same, every sample of a residence certain at once (switchobs_ros.switching: switch_horizon)
    "on-change-stamped-once": {"_channel": "stamped", "switch_horizon": 1.0},
    # camera_sim's pattern: the stamped channel on every tick, before the poses on a switching tick and
    # after them on the others (a heartbeat that proves the tick's poses as it arrives); and the same
    # messages with the channel before the poses on every tick (the last tenth of a residence then
    # waits one tick for the next heartbeat: switch_horizon 0.9)
    "every-tick-stamped": {"_channel": "tick"},
    "every-tick-stamped-first": {"_channel": "tick-first"},
}
#: The sender's channel patterns that publish the stamped ``switchobs_msgs/ActiveChannel``.
STAMPED = ("stamped", "tick", "tick-first")
#: The soak's goal: no answer later than this (ms).
LATE_MS = 20.0
#: ``--perf DIR``: record the machine's context switches (``perf record -a -e sched:sched_switch``)
#: and keep them, with the latencies, for the runs that had late or lost answers.
PERF_DIR: Path | None = None


# ----------------------------------------------------------------------------- roles
def republisher_main() -> None:
    """The ceiling: republish every target/pose as it arrives."""
    import rclpy
    from geometry_msgs.msg import PoseStamped
    from rclpy.executors import ExternalShutdownException
    from std_msgs.msg import UInt8

    from switchobs_ros import qos

    rclpy.init(args=sys.argv)
    node = rclpy.create_node("bare_republisher")
    pub = node.create_publisher(PoseStamped, "~/out", qos.OUTPUT)
    node.create_subscription(PoseStamped, "target/pose", pub.publish, qos.SENSOR_SUB)
    node.create_subscription(PoseStamped, "camera/pose", lambda m: None, qos.SENSOR_SUB)
    from switchobs_msgs.msg import ActiveChannel
    node.create_subscription(ActiveChannel if os.environ.get("BENCH_CHANNEL") in STAMPED else UInt8,
                             "camera/active_channel", lambda m: None, qos.CHANNEL_SUB)
    print("bare_republisher ready", flush=True)     # bench_startup.py: its interfaces exist
    try:
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()


def lean_estimator_main(args: list[str]) -> None:
    """The estimator node spun by a lean loop instead of ``rclpy.spin`` (an experiment on the executor's cost,
    the shipped node keeps ``switchobs_ros.runner``): one wait set holding only the three input
    subscriptions and the executor's SIGINT guard, built once and waited on again and again;
    what it finds is handled by the node's own :meth:`_drain_inputs`; the executor's full
    ``spin_once(0)`` (timers, services, parameter events) runs after every 10 ms of this."""
    import gc
    from contextlib import ExitStack

    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy

    from switchobs_core.threads import single_threaded_blas
    from switchobs_ros.estimator import EstimatorNode

    single_threaded_blas()
    rclpy.init(args=args)
    node = EstimatorNode()
    ex = SingleThreadedExecutor()
    ex.add_node(node)
    gc.freeze()
    ctx = node.context
    subs = [sub for sub, _ in node._hot_inputs]
    sigint = ex._sigint_gc
    period_ns = 10_000_000
    try:
        with ExitStack() as stack:
            for sub in subs:
                stack.enter_context(sub.handle)
            stack.enter_context(sigint.handle)
            stack.enter_context(ctx.handle)
            ws = _rclpy.WaitSet(len(subs), 1, 0, 0, 0, 0, ctx.handle)
            next_full = time.monotonic_ns()
            while ctx.ok():
                ws.clear_entities()
                for sub in subs:
                    ws.add_subscription(sub.handle)
                ws.add_guard_condition(sigint.handle)
                ws.wait(max(next_full - time.monotonic_ns(), 0))
                if ws.get_ready_entities("subscription"):
                    node._drain_inputs()
                now = time.monotonic_ns()
                if now >= next_full:
                    for _ in range(4):
                        ex.spin_once(timeout_sec=0)
                    next_full = now + period_ns
    except KeyboardInterrupt:
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()


def sender_main(ns: str, rate: float, seconds: float, out: str) -> None:
    """Publish ``rate * seconds`` pairs (after the node and the receiver are matched); save the stamps."""
    import rclpy
    from geometry_msgs.msg import PoseStamped
    from std_msgs.msg import UInt8

    import msg_bridge as mb
    from msg_bridge.typed import active_channel
    from switchobs_core.model.schedule import Cycle, PeriodicSchedule
    from switchobs_ros import qos

    # '' (channel 1 once), uint8, stamped (on change), tick, tick-first (every tick: CONFIGS)
    pattern = os.environ.get("BENCH_CHANNEL", "")
    stamped = pattern in STAMPED
    sched = PeriodicSchedule(Cycle.from_ts(2.0, 0.6))
    rclpy.init()
    node = rclpy.create_node("bench_sender")
    cam = node.create_publisher(PoseStamped, f"/{ns}/camera/pose", qos.SENSOR)
    tgt = node.create_publisher(PoseStamped, f"/{ns}/target/pose", qos.SENSOR)
    kind = type(active_channel(1, 0)) if stamped else UInt8
    ch = node.create_publisher(kind, f"/{ns}/camera/active_channel",
                               qos.CHANNEL_PUB)
    end = time.monotonic() + 60
    while (tgt.get_subscription_count() < 1 or cam.get_subscription_count() < 1 or ch.get_subscription_count() < 1):
        time.sleep(0.01)
        if time.monotonic() > end:
            raise SystemExit("sender: the node did not subscribe within 60 s")
    if not pattern:
        ch.publish(UInt8(data=1))
    time.sleep(0.2)
    current, instant = 0, 0
    n = int(rate * seconds)
    period = 1.0 / rate
    sent = np.zeros(n, dtype=np.int64)
    t_next = time.perf_counter()
    for k in range(n):
        d = t_next - time.perf_counter()
        if d > 0:
            time.sleep(d)       # no spinning: the sender must not compete with the node for a core
        s = time.time_ns()
        c = int(sched.channel_at(k * period))
        switching = c != current
        if switching:
            current, instant = c, s
        if pattern and (switching or pattern == "tick-first"):
            ch.publish(active_channel(c, instant) if stamped else UInt8(data=c))
        cam.publish(mb.xy_to_pose((0.001 * k, 0.0), s, "map"))
        tgt.publish(mb.xy_to_pose((3.0, 1.0), s, "map"))
        if pattern == "tick" and not switching:
            ch.publish(active_channel(c, instant))      # the heartbeat, after the tick's poses
        sent[k] = s
        t_next += period
    np.save(out, sent)
    time.sleep(0.5)
    node.destroy_node()
    rclpy.try_shutdown()


def receiver_main(topic: str, kind: str, out: str, witness: str = "") -> None:
    """Record ``(stamp, DDS reception, Python arrival)`` of every answer on ``topic`` until SIGINT;
    save them. The DDS reception (``MessageInfo.received_timestamp``, the system clock:
    ``bench/_receipt.py``) is the arrival the latency uses: the receiver's own queue stays out of
    it; the Python arrival (``time.time_ns()`` in the callback) is kept for comparison. With
    ``witness`` (a topic of the sender's), record its messages' ``(stamp, DDS reception, Python
    arrival)`` as well, in ``out`` + ``.witness.npy``: a second subscriber of the node's input, in
    another process, that tells whether a late answer's measurement was late everywhere (sender,
    middleware, machine) or only at the node.

    The callbacks keep the serialized message and its times only (``raw=True``), served by
    ``switchobs_ros.executor.KeptWaitSetExecutor``; the messages are deserialized after the run. The
    receiver shares this machine's two cores with the node under test (perf, 2026-11-23: in a
    20 ms cluster of late answers at 1000 Hz the receiver's thread ran 15.8 ms, the node's
    14.0 ms); deserializing later cut its CPU at 1000 Hz from 0.34-0.37 to 0.29-0.32 of a core."""
    import rclpy
    from _receipt import RECEIVE, check_system_clock
    from geometry_msgs.msg import PoseStamped
    from rclpy.executors import ExternalShutdownException
    from rclpy.serialization import deserialize_message
    from std_msgs.msg import Float64MultiArray

    from switchobs_ros import qos
    from switchobs_ros.executor import KeptWaitSetExecutor

    rclpy.init()
    node = rclpy.create_node("bench_receiver")
    got: list[tuple[bytes, int, int]] = []
    wit: list[tuple[bytes, int, int]] = []
    answer_type = Float64MultiArray if kind == "array" else PoseStamped
    node.create_subscription(answer_type, topic, lambda b, info: got.append(
        (b, info["received_timestamp"], time.time_ns())), RECEIVE, raw=True)
    if witness:
        node.create_subscription(PoseStamped, witness, lambda b, info: wit.append(
            (b, info["received_timestamp"], time.time_ns())), qos.SENSOR_SUB, raw=True)
    ex = KeptWaitSetExecutor()
    ex.add_node(node)
    try:
        ex.spin()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()

        def stamp(b: bytes, t: type) -> int:
            m = deserialize_message(b, t)
            if t is Float64MultiArray:
                return int(m.data[0]) * 1_000_000_000 + int(m.data[1])
            return m.header.stamp.sec * 1_000_000_000 + m.header.stamp.nanosec

        rec = np.array([(stamp(b, answer_type), dds, py) for b, dds, py in got], dtype=np.int64).reshape(-1, 3)
        check_system_clock(rec[:, [1, 1, 2]])
        np.save(out, rec)
        if witness:
            np.save(out + ".witness.npy",
                    np.array([(stamp(b, PoseStamped), dds, py) for b, dds, py in wit], dtype=np.int64).reshape(-1, 3))


# ----------------------------------------------------------------------------- orchestration
def _proc(name: str, args: list[str], tmp: Path):
    from tools.launch import NodeProcess

    return NodeProcess(name, cmd=[sys.executable, __file__, *args], log=tmp / f"{name}.log")


def _cpu_s(pid: int) -> float:
    """User + system CPU time of process ``pid`` so far (s), from /proc (nan where there is none)."""
    try:
        f = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
        return (int(f[11]) + int(f[12])) / os.sysconf("SC_CLK_TCK")
    except (OSError, IndexError, ValueError):
        return float("nan")


def measure(target: str, params: dict, rate: float, seconds: float, table: str, tmp: Path,
            env: dict | None = None) -> dict:
    """One run: start the node under test, the receiver and the sender; latency statistics and the
    node's CPU share while the sender sends (``cpu``: CPU seconds per wall second, 1.0 = one core)."""
    from tools.launch import NodeProcess, ros_args

    ns = "m"
    for f in ("sent.npy", "recv.npy"):
        (tmp / f).unlink(missing_ok=True)
    if target == "bare":
        node = NodeProcess("republisher", ["-r", f"__ns:=/{ns}"],
                           cmd=[sys.executable, __file__, "--republisher", "--ros-args"], log=tmp / "rep.log")
        topic, kind = f"/{ns}/bare_republisher/out", "pose"
    else:
        lean = params.pop("_lean", False)
        traced = params.pop("_trace", False)
        chrt = params.pop("_chrt", 0)
        (tmp / "trace.npz").unlink(missing_ok=True)
        cmd = ([sys.executable, __file__, "--lean-estimator"] if lean else
               [sys.executable, str(Path(__file__).with_name("trace_node.py")), str(tmp / "trace.npz")] if traced
               else [sys.executable, "-m", "switchobs_ros.estimator"])
        if chrt:
            cmd = ["chrt", "-f", str(chrt), *cmd]
        node = NodeProcess("estimator", ros_args(params={"gain_table": table, **params}) + ["-r", f"__ns:=/{ns}"],
                           cmd=cmd, log=tmp / "estimator.log", env=None if env is None else {**os.environ, **env})
        topic, kind = f"/{ns}/estimator/state", "array"
    (tmp / "recv.npy.witness.npy").unlink(missing_ok=True)
    recv = _proc("receiver", ["--receiver", topic, kind, str(tmp / "recv.npy"), f"/{ns}/target/pose"], tmp)
    perf = None
    try:
        time.sleep(2.0)         # start-up and discovery (the sender waits for the node's subscriptions)
        send = _proc("sender", ["--sender", ns, str(rate), str(seconds), str(tmp / "sent.npy")], tmp)
        if PERF_DIR is not None:    # the whole machine (the sender starts sending after 0.2 s)
            perf = subprocess.Popen(["perf", "record", "-q", "-k", "CLOCK_MONOTONIC", "-e", "sched:sched_switch",
                                     "-a", "-o", str(tmp / "perf.data")],      # -a: switches in, too
                                    stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        c0, r0, w0 = _cpu_s(node.pid), _cpu_s(recv.pid), time.monotonic()
        send.wait(timeout=seconds + 120)
        c1, r1, w1 = _cpu_s(node.pid), _cpu_s(recv.pid), time.monotonic()
        time.sleep(1.0)         # the last answers
    finally:
        if perf is not None:
            perf.send_signal(signal.SIGINT)
            perf.wait(timeout=60)
        recv.stop(timeout=60)    # it deserializes what it received before saving
        node.stop()
    sent = np.load(tmp / "sent.npy")
    if not (tmp / "recv.npy").exists():
        raise RuntimeError(f"the receiver saved no answers (its log: {tmp / 'receiver.log'})")
    rec = np.load(tmp / "recv.npy")
    arrival = dict(zip(rec[:, 0].tolist(), rec[:, 1].tolist()))         # DDS reception
    python_arrival = dict(zip(rec[:, 0].tolist(), rec[:, 2].tolist()))
    lat = np.array([(arrival[s] - s) * 1e-6 for s in sent.tolist() if s in arrival])
    lat_py = np.array([(python_arrival[s] - s) * 1e-6 for s in sent.tolist() if s in arrival])
    achieved = (len(sent) - 1) / ((sent[-1] - sent[0]) * 1e-9) if len(sent) > 1 else 0.0
    late_ms = LATE_MS if rate <= 500 else 5.0
    if PERF_DIR is not None and (lat.size < len(sent) or (lat > late_ms).any()):
        k = len(list(PERF_DIR.glob("*.data")))
        (tmp / "perf.data").rename(PERF_DIR / f"run{k}.data")
        np.savez(PERF_DIR / f"run{k}.npz", sent=sent, rec=rec, node_pid=node.pid, sender_pid=send.pid,
                 receiver_pid=recv.pid, realtime_minus_monotonic_ns=time.time_ns() - time.monotonic_ns())
    trace = witness_split(np.load(tmp / "recv.npy.witness.npy"), sent, arrival, late_ms)
    if target != "bare" and (tmp / "trace.npz").exists():
        from trace_node import split
        trace += "; " + split(tmp / "trace.npz", sent, arrival, late_ms)
    return {"rate": rate, "achieved": achieved, "sent": len(sent), "answered": len(lat), "lat": lat,
            "cpu": (c1 - c0) / (w1 - w0), "receiver_cpu": (r1 - r0) / (w1 - w0), "trace": trace,
            "p50": float(np.median(lat)) if lat.size else np.nan,
            "p99": float(np.percentile(lat, 99)) if lat.size else np.nan,
            "p50_py": float(np.median(lat_py)) if lat.size else np.nan,
            "max": float(lat.max()) if lat.size else np.nan}


def witness_split(wit: np.ndarray, sent: np.ndarray, arrival: dict, late_ms: float) -> str:
    """The answers later than ``late_ms`` and the lost ones, against the witness (a second
    subscriber of target/pose in the receiver's process): how many of their measurements also
    reached the witness later than ``late_ms / 2``, or never."""
    w = dict(zip(wit[:, 0].tolist(), wit[:, 1].tolist()))
    late = [s for s in sent.tolist() if s in arrival and (arrival[s] - s) * 1e-6 > late_ms]
    lost = [s for s in sent.tolist() if s not in arrival]
    if not late and not lost:
        return ""

    def slow(s: int) -> bool:
        return s not in w or (w[s] - s) * 1e-6 > late_ms / 2

    return (f"witness: {sum(map(slow, late))} of the {len(late)} late answers' measurements and "
            f"{sum(map(slow, lost))} of the {len(lost)} lost ones were also late (> {late_ms / 2:g} ms) or missing "
            f"at the witness; the witness missed {sum(s not in w for s in sent.tolist())} of {len(sent)}")


def figure(results: dict, rates: list[float], path: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter

    fig, axes = plt.subplots(1, len(rates), figsize=(3.6 * len(rates), 3.4), constrained_layout=True, sharey=True)
    axes = np.atleast_1d(axes)
    for ax, rate in zip(axes, rates):
        allv = np.concatenate([r["lat"] for rs in results.values() for r in rs if r["rate"] == rate and r["lat"].size])
        hi = float(np.percentile(allv, 99.9)) * 1.2 if allv.size else 10.0
        bins = np.logspace(np.log10(max(allv.min(), 0.05)) if allv.size else -1, np.log10(max(hi, 0.2)), 50)
        for name, rs in results.items():
            r = next(r for r in rs if r["rate"] == rate)
            if r["lat"].size:
                ax.hist(r["lat"], bins=bins, histtype="step", lw=1.4, density=True,
                        label=f"{name}: p99 {r['p99']:.2f} ms ({r['answered']}/{r['sent']})")
        ax.set_xscale("log")
        ax.xaxis.set_major_locator(LogLocator(subs=(1.0, 2.0, 5.0)))
        ax.xaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
        ax.xaxis.set_minor_formatter(NullFormatter())
        ax.set_title(f"{rate:g} Hz", fontsize=10)
        ax.set_xlabel("latency [ms]")
        ax.legend(fontsize=6.5, loc="upper right")
        ax.grid(True, which="both", alpha=0.25)
    axes[0].set_ylabel("density")
    fig.suptitle("estimator vs bare rclpy republisher: latency of each answer (bench/bench_node.py)", fontsize=10)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main(argv=None) -> int:
    args = sys.argv[1:] if argv is None else argv
    if args[:1] == ["--republisher"]:
        republisher_main()
        return 0
    if args[:1] == ["--lean-estimator"]:
        lean_estimator_main(args[1:])
        return 0
    if args[:1] == ["--sender"]:
        sender_main(args[1], float(args[2]), float(args[3]), args[4])
        return 0
    if args[:1] == ["--receiver"]:
        receiver_main(*args[1:5])
        return 0
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seconds", type=float, default=5.0)
    ap.add_argument("--rates", default="100,250,500,1000")
    ap.add_argument("--configs", default="default,no-gc-freeze,state-only",
                    help=f"estimator configurations: {', '.join(CONFIGS)}")
    ap.add_argument("--repeat", type=int, default=1,
                    help="runs per rate and node, interleaved; the table gives medians over the runs (the ratio: "
                         "the median of each run's p99 over the republisher's p99 of the same round)")
    ap.add_argument("--soak", type=float, default=0.0, help="seconds of a 500 Hz soak of the default estimator")
    ap.add_argument("--soak-repeat", type=int, default=1, help="number of soaks")
    ap.add_argument("--soak-config", default="default", help="configurations of the soaks, comma-separated, "
                    "interleaved --soak-repeat times (traced: with a trace of where the late answers' time went, "
                    "bench/trace_node.py; bare: the republisher under the same soak)")
    ap.add_argument("--domain", type=int, default=None, help="ROS_DOMAIN_ID to use (default: claim a free one)")
    ap.add_argument("--base", default=None, metavar="DIR",
                    help="also run, as configuration 'base', the default estimator of the source tree DIR (e.g. "
                         "`git archive <commit> | tar -x -C DIR`; run the bench from another directory, so that "
                         "`python -m` does not import the current directory's package)")
    ap.add_argument("--load", type=int, default=0, metavar="K",
                    help="K busy-looping processes (ordinary priority) run through every measurement: a busy "
                         "machine")
    ap.add_argument("--perf", type=Path, default=None, metavar="DIR",
                    help="record the machine's context switches with perf (sched:sched_switch) and keep "
                         "them in DIR for the runs with late or lost answers (under perf the receiver exited "
                         "without saving in 2 of about 30 runs on 2026-11-23: the run then stops with that message)")
    ap.add_argument("--figure", type=Path, default=None)
    a = ap.parse_args(args)
    global PERF_DIR
    if a.perf is not None:
        a.perf.mkdir(parents=True, exist_ok=True)
        PERF_DIR = a.perf
    from tools.domain import claim_domain, localhost_env

    lease = claim_domain()
    os.environ.update(localhost_env(lease.domain_id if a.domain is None else a.domain))
    from switchobs_core.design.lmi import design_table
    from switchobs_core.model.scenarios import load_system
    from switchobs_core.model.schedule import Cycle

    tmp = Path(tempfile.mkdtemp(prefix="bench_node_"))
    table = str(design_table(load_system("paper"), [Cycle.from_ts(2.0, 0.6)], progress=False).save(tmp / "p.json"))
    rates = [float(r) for r in a.rates.split(",")]
    configs = [c for c in a.configs.split(",") if c] + (["base"] if a.base else [])

    def run(c: str, rate: float, seconds: float) -> dict:
        if c == "bare":
            return measure("bare", {}, rate, seconds, table, tmp)
        if c == "base":
            return measure("estimator", {}, rate, seconds, table, tmp, env={"PYTHONPATH": str(Path(a.base).resolve())})
        params = dict(CONFIGS[c])
        env = params.pop("_env", None)
        os.environ["BENCH_CHANNEL"] = params.pop("_channel", "")      # the sender's channel pattern
        try:
            return measure("estimator", params, rate, seconds, table, tmp, env=env)
        finally:
            os.environ["BENCH_CHANNEL"] = ""

    hogs = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(a.load)]
    names = {c: f"estimator ({c})" for c in configs}
    names["bare"] = "bare republisher"
    runs: dict[str, list[list[dict]]] = {n: [[] for _ in rates] for n in names.values()}
    try:
        for i, rate in enumerate(rates):
            for _ in range(a.repeat):
                for c in [*configs, "bare"]:
                    runs[names[c]][i].append(run(c, rate, a.seconds))
                    r = runs[names[c]][i][-1]
                    sys.stderr.write(f"{rate:g} Hz {names[c]}: {r['answered']}/{r['sent']}, p99 {r['p99']:.3f} ms, "
                                     f"max {r['max']:.2f} ms, cpu {r['cpu']:.2f} (receiver "
                                     f"{r['receiver_cpu']:.2f}) {r['trace']}\n")
        soak_configs = [c for c in a.soak_config.split(",") if c]
        soaks = []
        for _ in range(a.soak_repeat if a.soak > 0 else 0):
            for c in soak_configs:
                soaks.append((c, run(c, 500.0, a.soak)))
                r = soaks[-1][1]
                sys.stderr.write(f"soak {c}: {r['answered']}/{r['sent']}, max {r['max']:.2f} ms, "
                                 f"{int(np.sum(r['lat'] > LATE_MS))} late\n")
    finally:
        for h in hogs:
            h.kill()
            h.wait()
    lease.release()

    def med(rs: list[dict], k: str) -> float:
        return float(np.median([r[k] for r in rs]))

    results = {n: [{"rate": rate, "lat": np.concatenate([r["lat"] for r in rs[i]]), "p99": med(rs[i], "p99"),
                    "answered": sum(r["answered"] for r in rs[i]), "sent": sum(r["sent"] for r in rs[i])}
                   for i, rate in enumerate(rates)] for n, rs in runs.items()}
    print(f"### Estimator node over DDS (bench/bench_node.py)\n\n"
          f"{time.strftime('%Y-%m-%d')}, {platform.node()}, {os.cpu_count()} cores, Python "
          f"{platform.python_version()}, ROS 2 Jazzy wheels (rmw_fastrtps_cpp), localhost only; {a.seconds:g} s "
          "per rate and node; sender, receiver and node in separate processes; each measurement is a "
          f"camera/pose + target/pose pair; {a.repeat} run(s) per rate and node, interleaved"
          + (f"; **{a.load} busy-looping processes** running throughout" if a.load else "")
          + (" (medians over the runs; answered: summed)" if a.repeat > 1 else "") + ". Node CPU: CPU seconds "
          "of the node's process per second while the sender sends (1.00 = one core).\n")
    print("| rate (Hz) | node | answered | p50 (ms) | p50 at the receiver's Python (ms) | p99 (ms) | max (ms) "
          "| node CPU | p99 / republisher's |")
    print("|---:|---|---:|---:|---:|---:|---:|---:|---:|")
    for i, rate in enumerate(rates):
        bare = runs["bare republisher"][i]
        for name, rs in runs.items():
            r = rs[i]
            ratio = float(np.median([x["p99"] / b["p99"] for x, b in zip(r, bare)]))
            print(f"| {rate:g} | {name} | {sum(x['answered'] for x in r)}/{sum(x['sent'] for x in r)} "
                  f"| {med(r, 'p50'):.3f} | {med(r, 'p50_py'):.3f} | {med(r, 'p99'):.3f} | {med(r, 'max'):.2f} "
                  f"| {med(r, 'cpu'):.2f} | {ratio:.2f} |")
    full = {name: max([rate for i, rate in enumerate(rates) if all(x["answered"] == x["sent"] for x in rs[i])],
                      default=0.0) for name, rs in runs.items()}
    print("\nHighest rate answered in full: " + ", ".join(f"{k} {v:g} Hz" for k, v in full.items()) + ".")
    for c, soak in soaks:
        late = int(np.sum(soak["lat"] > LATE_MS))
        print(f"\n- Soak: {names.get(c, f'estimator ({c})')} at 500 Hz for {a.soak:g} s: "
              f"{soak['answered']}/{soak['sent']} "
              f"answered, p50 {soak['p50']:.3f} ms, p99 {soak['p99']:.3f} ms, max {soak['max']:.2f} ms, "
              f"{late} answers later than {LATE_MS:g} ms, node CPU {soak['cpu']:.2f}"
              + (f"; {soak['trace']}" if soak["trace"] else "") + ".")
    if a.figure:
        figure(results, rates, a.figure)
        rel = os.path.relpath(a.figure.resolve(), Path(__file__).resolve().parent)
        print(f"\n![latency histograms]({rel})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
