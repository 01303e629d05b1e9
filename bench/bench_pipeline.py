#!/usr/bin/env python
"""The estimator's CPU per sample at 32 agents (n = 132), in process: camera_sim's stream through
the node's input handler and outputs without DDS, over the Kalman table's first visits and at
steady state, against the core alone (not a test; bench/RESULTS.md).

    python bench/bench_pipeline.py [--table /tmp/boot/k32v4.npz] [--rounds 3] [--before /work/main]
    python bench/bench_pipeline.py --cprofile 30 --window steady      # where the time goes

The stream is camera_sim's (``camera_agents`` with M agents, every ``h_i = 1 s``, ``rate`` Hz,
stamped on its grid, the switching instant in the stamped channel message): the channel message,
``camera/pose`` and ``target/pose`` of every tick, serialised once in this process and read back in
each child before its timed part, so every tree is fed the same bytes.

Each child (one tree: this checkout or ``--before``) builds the estimator as the node does
(:class:`~switchobs_ros.estimator.EstimatorMixin` on a stand-in for the rclpy node: its
``_configure``, its input handler ``_input_handler`` and its outputs ``_publish_all``, the raw writers of
:mod:`msg_bridge.raw`), every output listened, publishers that drop the bytes; then feeds each
message with a ``MessageInfo`` of source and receive timestamps and sequence numbers, as rclpy
does. What it does not run: rclpy's executor, the drain's takes, the middleware. The outputs are
the goal's configuration (``~/state`` and ``~/envelope`` every sample; odometry, covariance and
the typed pair every 5th; markers every 10th: ``--every``). The parameters are
``bench_live_scale.py``'s (``e0`` 1e3, every ``h_i`` 1 s) with ``max_abs_value`` 1e12: agent 1's
unstable mode (0.2/s) carries its position past the default 1e6 m at about 70 s, and the
steady window runs past that.

``--drop F`` drops a fraction ``F`` of the ticks after the first second (both poses of the tick;
its channel message kept), drawn with a fixed seed, so every tree misses the same ticks, as the
node misses the ticks camera_sim skips when it runs late (a loaded machine): each missing sample
takes a Kalman table out of its cache into the online recursion until it re-locks. CPU is then
reported per answer (the window's CPU over its answers).

``--what core`` times the core alone on the same samples: ``SwitchedObserver.update`` and
``envelope()`` of the observer the pipeline builds (no pairing, attribution, screening, tests or
outputs). ``--what screen`` adds what the pipeline's screening asks of the core before each
update (:meth:`switchobs_ros.screening.Screening.admit`): the innovation test against
``prior(t)`` and the bias test (``Recovery.before``: the held prediction and the prior
covariance's block), the per-sample core path. Both print a digest of every estimate and bound
(the trees' numbers compared).

Reported per tree and window (``first``: 0 to ``--first`` s, all first visits of the table's
phases; ``steady``: one table period from ``--steady`` s): CPU per sample (``time.process_time``,
the total over the window divided by the samples, the goal's "CPU per answer") and the median
sample, medians over interleaved rounds, and the ratio after/before in the same run.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]


# ---------------------------------------------------------------------------- the stream
def make_stream(agents: int, rate: float, seconds: float, out: Path) -> None:
    """camera_sim's ticks for ``seconds``: ``out`` (an ``.npz``) holds each message serialised
    (topic, type and bytes per message, in publication order), each tick's stamp, channel and
    output ``y`` (the core-alone run reads those)."""
    sys.path.insert(0, str(REPO))
    import yaml
    from rclpy.serialization import serialize_message

    import msg_bridge as mb
    import switchobs_core as so
    from switchobs_core.model.schedule import PeriodicSchedule
    from switchobs_core.sim.plant import Plant
    from switchobs_ros.core_config import SensorOutputs

    sys_path = out.with_suffix(".yaml")
    sys_path.write_text(yaml.safe_dump({"scenario": "camera_agents", "agents": agents}))
    system = so.load_system(sys_path)
    sched = PeriodicSchedule(so.Cycle([1.0] * agents))
    x0 = np.random.default_rng(1).uniform(-1.0, 1.0, 4 * (agents + 1))     # as bench_live_scale.py
    plant = Plant(system, x0, seed=0)
    specs = mb.load_inputs(str(sys_path), system)
    outputs = SensorOutputs(specs)
    period = round(1e9 / rate)
    epoch = 1_800_000_000_000_000_000
    topics, types, blobs, tick_of = [], [], [], []
    stamps, chans, ys = [], [], []
    switch = (0, 0)
    for k in range(int(round(seconds * rate))):
        stamp = epoch + k * period
        t = k * period * 1e-9
        plant.advance(t)
        rho = int(sched.channel_at(t))
        y = plant.measure(rho)
        switching = rho != switch[0]
        if switching:
            switch = (rho, stamp)
        for topic, msg in outputs.messages(rho, y, stamp, "map", sched.blind_at(t), switch[1], switching=switching):
            topics.append(topic)
            types.append(f"{type(msg).__module__.split('.')[0]}/msg/{type(msg).__name__}")
            blobs.append(np.frombuffer(serialize_message(msg), dtype=np.uint8))
            tick_of.append(k)
        stamps.append(stamp)
        chans.append(rho)
        ys.append(np.asarray(y, dtype=float))
    offsets = np.cumsum([0] + [b.size for b in blobs])
    np.savez(out, topics=np.array(topics), types=np.array(types), data=np.concatenate(blobs),
             offsets=offsets, tick_of=np.array(tick_of), stamps=np.array(stamps, dtype=np.int64),
             channels=np.array(chans), y=np.array(ys), system=str(sys_path))


# ---------------------------------------------------------------------------- one child
class _Logger:
    def info(self, *_a, **_k):
        pass

    warn = error = debug = warning = info


class _Now:
    __slots__ = ("nanoseconds",)

    def __init__(self):
        self.nanoseconds = 0


class _Clock:
    """The node clock of the stand-in: the receive time of the message being handled."""

    def __init__(self):
        self.t = _Now()
        self.handle = self       # rclpy's Clock.handle: get_now() is rcl's time point, as the node reads it

    def now(self):
        return self.t

    def get_now(self):
        return self.t


class _Publisher:
    """A publisher with one matched subscription that drops what it is given (counts it; with
    ``digest``, a hashlib object, hashes its topic and the bytes, a message object serialised)."""

    digest = None

    def __init__(self, topic_name: str = "/estimator/out"):
        self.n = 0
        self.topic_name = topic_name     # what bench/phases.py names a publish by
        self.handle = self               # the rcl publisher: the node's serialised writes (publish_raw)

    def get_subscription_count(self) -> int:
        return 1

    def publish(self, msg) -> None:
        self.n += 1
        if _Publisher.digest is not None:     # serialised, its padding zeroed (rclpy leaves heap bytes there)
            from rclpy.serialization import serialize_message

            from msg_bridge.cdr_padding import zero_padding
            self.publish_raw(zero_padding(msg, serialize_message(msg)))
            self.n -= 1

    def publish_raw(self, data) -> None:
        self.n += 1
        data = memoryview(data).tobytes()   # rclpy's publish_raw copies what it is given (pybind11's std::string)
        if _Publisher.digest is not None:
            _Publisher.digest.update(self.topic_name.encode() + b"\0" + data)


def stream_inputs(s: dict, node) -> tuple[list, dict, dict]:
    """The stream's messages (``s``: :func:`make_stream`'s) as the node takes them, the node's input
    handler per topic and a sequence counter per topic (the benchmarks' replay loop)."""
    import importlib

    from rclpy.serialization import deserialize_message

    topics, types, data, offsets = s["topics"], s["types"], s["data"], s["offsets"]
    classes = {t: getattr(importlib.import_module(t.split("/")[0] + ".msg"), t.split("/")[2])
               for t in set(types.tolist())}
    msgs = [deserialize_message(data[offsets[i]:offsets[i + 1]].tobytes(), classes[types[i]])
            for i in range(len(topics))]
    pl = node.pipeline
    index = {src.topic: src.index for src in pl.sources}
    handlers = {t: node._input_handler(None if t == pl.channel_topic else index[t]) for t in set(topics.tolist())}
    return msgs, handlers, dict.fromkeys(handlers, 0)


def deliver(handlers: dict, seq: dict, clock, topic: str, msg, sent_ns: int) -> None:
    """``msg`` to the node's handler of ``topic`` as the middleware hands it: sent at ``sent_ns``,
    received (the node clock ``clock`` set to it) 0.3 ms later, the topic's next sequence number."""
    seq[topic] += 1
    clock.t.nanoseconds = sent_ns + 300_000
    handlers[topic](msg, {"source_timestamp": sent_ns, "received_timestamp": sent_ns + 300_000,
                          "publication_sequence_number": seq[topic]})


def _bench_node(cfg: dict):
    """The estimator's behaviour (``EstimatorMixin``) on a stand-in for the rclpy node, every
    output with a listened publisher."""
    from switchobs_ros.estimator import EstimatorMixin

    clock = _Clock()

    class BenchNode(EstimatorMixin):
        def get_logger(self):
            return _Logger()

        def get_namespace(self):
            return "/"

        def get_fully_qualified_name(self):
            return "/estimator"

        def get_clock(self):
            return clock

    node = BenchNode()
    node.cfg = cfg
    node._configure(cfg)
    node.pub_state, node.pub_env, node.pub_cov, node.pub_markers = (
        _Publisher(f"/estimator/{k}") for k in ("state", "envelope", "covariance", "markers"))
    node.pub_odom = [_Publisher(f"/estimator/body{i}/odom") for i in range(len(node.bodies))]
    node.pub_typed = (_Publisher("/estimator/typed/estimate"), _Publisher("/estimator/typed/bounds"))
    if not hasattr(node, "w_cov"):        # made with the covariance's publisher (_create_interfaces)
        import msg_bridge as mb
        from msg_bridge.raw import RawLabelledArrayWriter
        node.w_cov = RawLabelledArrayWriter(mb.covariance_labels(node.state_labels))
    return node, clock


def run_child(a) -> dict:
    """One tree, one run: the stream through the node's handler (or the core alone); per-sample
    CPU times in each window (JSON on stdout)."""
    sys.path.insert(0, str(a.child))
    import gc

    from switchobs_ros.heap import keep_heap
    keep_heap()     # glibc's heap kept between samples, as the node's console script sets it (switchobs_ros.entry)

    from switchobs_core.threads import single_threaded_blas
    from switchobs_ros.config import params_from_file

    single_threaded_blas()
    s = np.load(a.stream)
    agents = int(a.agents)
    every = {k: int(v) for k, v in (kv.split("=") for kv in a.every.split(",") if kv)}
    cfg = params_from_file(overrides={"system": str(s["system"]), "gain_table": a.table,
                                      "schedule.mode": "periodic", "schedule.h": tuple([1.0] * agents),
                                      "e0": 1e3, "max_abs_value": 1e12,
                                      **{f"output.{k}_every": v for k, v in every.items()}})
    ph = None
    if a.phases:        # bench/phases.py: the thread's CPU by phase, installed before the node is built
        sys.path.insert(0, str(REPO / "bench"))
        import phases as ph
        ph.install(fine=bool(os.environ.get("SWITCHOBS_PHASES_FINE")))
    node, clock = _bench_node(cfg)
    import switchobs_core
    assert switchobs_core.__file__.startswith(str(a.child)), switchobs_core.__file__
    pl = node.pipeline
    stamps, tick_of = s["stamps"], s["tick_of"]
    rate = 1e9 / float(stamps[1] - stamps[0])
    k_first = int(round(a.first * rate))
    k0, k1 = int(round(a.steady * rate)), int(round((a.steady + a.steady_len) * rate))
    n_ticks = min(k1, len(stamps))
    cost = np.zeros(n_ticks)
    prof = None
    if a.cprofile:
        import cProfile
        prof = cProfile.Profile(time.process_time)
    lo, hi = (0, k_first) if a.window == "first" else (k0, n_ticks)
    served: dict = {}
    screened = 0
    digest = None
    tests = np.zeros(n_ticks)       # screen: the tests' share of each sample's CPU
    if a.what in ("core", "screen"):
        obs = pl.observer
        obs.reset(pl.x0, 0.0)
        y, ch = s["y"], s["channels"]
        scr = pl.screening
        screen = a.what == "screen"
        if screen:      # the screening's calls, as Screening.admit makes them (the pipeline's objects)
            from switchobs_core.runtime.recovery import Recovery
            rec = Recovery(obs, labels=scr.labels)
            import inspect
            kw = {"lazy": True} if "lazy" in inspect.signature(obs.prior).parameters else {}    # as the screening
        import hashlib
        digest = hashlib.sha256()       # of every estimate and bound: the trees' numbers compared
        gc.freeze()
        for k in range(n_ticks):
            t = (int(stamps[k]) - int(stamps[0])) * 1e-9
            c0 = time.process_time()
            if prof is not None and k == lo:
                prof.enable()
            if screen:
                c = int(ch[k])
                with np.errstate(all="ignore"):
                    ok = scr.innovation.check(obs.prior(t, **kw), c, None, y[k]).ok
                rec.before(t, c, None, y[k])
                screened += ok
                tests[k] = time.process_time() - c0
            obs.update(t, int(ch[k]), y[k])
            env = obs.envelope()
            digest.update(obs.x_hat.tobytes())
            digest.update(np.array([env.exact_bound, -1.0 if env.noise_bound is None else env.noise_bound]).tobytes())
            if prof is not None and k == hi - 1:
                prof.disable()
            cost[k] = time.process_time() - c0
        answers = n_ticks
        answered = np.ones(n_ticks, dtype=bool)     # --drop: the pipeline only
    else:
        topics = s["topics"]
        msgs, handlers, seq = stream_inputs(s, node)
        if a.digest:        # every published message's bytes, by topic, in order (timing distorted)
            import hashlib
            digest = _Publisher.digest = hashlib.sha256()
        dropped = np.random.default_rng(7).random(n_ticks) < a.drop
        dropped[:int(rate)] = False
        gc.freeze()
        evict = None
        if a.evict:     # between ticks: other work through the caches, as the node's 20 ms between ticks
            junk = np.zeros(int(a.evict * 2**20), dtype=np.uint8)

            def evict():
                junk[::64] += 1      # every cache line, written
            if ph is not None:
                evict = ph.timed(evict, "bench: evict")
        pace = None
        if a.pace:      # the ticks at their rate: the thread idles between them, as the node's, or spins

            def pace(until: float) -> None:
                if a.pace == "sleep":
                    time.sleep(max(0.0, until - time.monotonic()))
                while a.pace == "spin" and time.monotonic() < until:
                    pass
            if ph is not None:
                pace = ph.timed(pace, "bench: pace")
        i, done = 0, 0
        t_pace = time.monotonic()
        for k in range(n_ticks):
            c0 = time.process_time()
            if prof is not None and k == lo:
                prof.enable()
            if ph is not None and k == lo:
                ph.start()
                done_lo = pl.updates
            while i < len(topics) and tick_of[i] == k:
                topic = topics[i]
                if dropped[k] and topic != pl.channel_topic:
                    i += 1
                    continue
                deliver(handlers, seq, clock, topic, msgs[i], int(stamps[k]) + 100_000 * (1 + i % 3))
                i += 1
            if prof is not None and k == hi - 1:
                prof.disable()
            if ph is not None and k == hi - 1:
                phase_report = ph.report(pl.updates - done_lo)
            cost[k] = time.process_time() - c0
            if evict is not None:
                evict()
            if pace is not None:
                pace(t_pace + (k + 1) / rate)
            if pl.updates > done:       # the answers of this tick: served online or from the table
                served[pl.observer.gains_source] = served.get(pl.observer.gains_source, 0) + pl.updates - done
                done = pl.updates
        answers = pl.updates
        answered = ~dropped[:n_ticks]
    if a.digest and a.what == "pipeline":      # and the counters the diagnostics report
        digest.update(repr((sorted(pl.accepted.items()), sorted(pl.rejected.items()), sorted(pl.dropped.items()),
                            pl.updates, pl.parts_used, pl.partial_updates, pl.switches, pl.late_channel,
                            pl.lost_channel, sorted(pl.loss.lost.items()), sorted(pl.loss.restarts.items()),
                            pl.bound_valid, pl.bound_invalid_why, sorted(node.published.items()))).encode())
    if pl.errors or sum(pl.rejected.values()):
        sys.exit(f"the stream was not answered cleanly: {dict(pl.rejected)}; {pl.last_rejection}")
    out = {"answers": int(answers), "ticks": n_ticks, "first": cost[:k_first].tolist(),
           "steady": cost[k0:n_ticks].tolist(), "errors": int(pl.errors),
           "published": dict(getattr(node, "published", {})),
           "first_n": int(answered[:k_first].sum()), "steady_n": int(answered[k0:n_ticks].sum()),
           "online": served.get("online", 0), "screened": int(screened),
           "digest": digest.hexdigest()[:16] if digest is not None else "",
           "tests_first": float(np.sum(tests[:k_first])), "tests_steady": float(np.sum(tests[k0:n_ticks])),
           "kalman": {k: int(getattr(pl.observer.gains, k, -1))
                      for k in ("departures", "relocks", "gaps", "gaps_retired")}}
    if ph is not None:
        out["phases"] = phase_report
    if prof is not None:
        import io
        import pstats
        buf = io.StringIO()
        st = pstats.Stats(prof, stream=buf)
        st.sort_stats("tottime").print_stats(a.cprofile)
        st.sort_stats("cumulative").print_stats(a.cprofile)
        out["profile"] = buf.getvalue()
    return out


# ---------------------------------------------------------------------------- the parent
def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--agents", type=int, default=32)
    ap.add_argument("--rate", type=float, default=50.0)
    ap.add_argument("--table", default="/tmp/boot/k32v4.npz", help="the Kalman table of the model and schedule")
    ap.add_argument("--first", type=float, default=60.0, help="the first-visit window: 0 to this (s)")
    ap.add_argument("--steady", type=float, default=72.0, help="the steady window's start (s)")
    ap.add_argument("--steady-len", type=float, default=32.0, help="the steady window's length (s; one period)")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--before", type=Path, default=None, help="a checkout to compare with (e.g. /work/main)")
    ap.add_argument("--what", default="pipeline,core",
                    help="pipeline, core, screen (the core with the innovation and bias tests), comma-separated")
    ap.add_argument("--every", default="envelope=1,odometry=5,covariance=5,typed=5,markers=10",
                    help="output.<K>_every values")
    ap.add_argument("--cprofile", type=int, default=0, metavar="K",
                    help="one run of this checkout under cProfile, print the K costliest functions")
    ap.add_argument("--phases", action="store_true",
                    help="one run of this checkout (and --before) with bench/phases.py: the CPU by phase in --window")
    ap.add_argument("--evict", type=float, default=0.0, metavar="MB",
                    help="between ticks, write every cache line of a buffer of MB MiB (untimed; with --phases "
                         "left out of the phases): the caches as cold as other processes leave them")
    ap.add_argument("--pace", choices=("sleep", "spin"), default=None,
                    help="feed the ticks at their rate instead of back to back, the thread sleeping between them "
                         "(as the node's) or spinning (the core kept busy); untimed (with --phases: not in the phases)")
    ap.add_argument("--window", default="steady", choices=("first", "steady"), help="the window --cprofile profiles")
    ap.add_argument("--drop", type=float, default=0.0, metavar="F",
                    help="drop this fraction of the ticks (both poses; the same ticks in every tree)")
    ap.add_argument("--digest", action="store_true",
                    help="the pipeline child also hashes every published message's bytes (by topic, in order) and "
                         "the counters, printed with the core's digests (its CPU times then include the hashing)")
    ap.add_argument("--stream", type=Path, default=None, help=argparse.SUPPRESS)
    ap.add_argument("--child", type=Path, default=None, help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    if a.child is not None:
        print(json.dumps(run_child(a)))
        return 0
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1", PYTHONDONTWRITEBYTECODE="")
    with tempfile.TemporaryDirectory(prefix="bench_pipeline_") as tmp:
        stream = Path(tmp) / "stream.npz"
        make_stream(a.agents, a.rate, a.steady + a.steady_len, stream)
        trees = [("this", REPO)] + ([("before", a.before.resolve())] if a.before else [])
        whats = [w for w in a.what.split(",") if w]

        def child(tree: Path, what: str, extra: list[str] = ()) -> dict:
            cmd = [sys.executable, str(Path(__file__).resolve()), "--child", str(tree), "--stream", str(stream),
                   "--what", what, "--agents", str(a.agents), "--table", a.table, "--first", str(a.first),
                   "--steady", str(a.steady), "--steady-len", str(a.steady_len), "--every", a.every,
                   "--drop", str(a.drop), *(["--evict", str(a.evict)] if a.evict and "--evict" not in extra else []),
                   *(["--pace", a.pace] if a.pace else []), *(["--digest"] if a.digest else []),
                   *extra]
            r = subprocess.run(cmd, env=dict(env, PYTHONPATH=str(tree)), capture_output=True, text=True)
            if r.returncode:
                sys.exit(f"child {tree} {what} failed:\n{r.stderr[-4000:]}")
            return json.loads(r.stdout.strip().splitlines()[-1])

        if a.phases:
            got = {f"{name}, evict {mb:g} MiB" if mb else name: child(tree, "pipeline", [
                "--phases", "--window", a.window, "--evict", str(mb)])["phases"]
                for name, tree in trees for mb in dict.fromkeys([0.0, a.evict])}
            print(f"In process (`--phases --window {a.window}`), own CPU per answer by phase (bench/phases.py):\n")
            sys.path.insert(0, str(REPO / "bench"))
            import phases as ph
            print(ph.table(got))
            return 0
        if a.cprofile:
            for what in whats:
                r = child(REPO, what, ["--cprofile", str(a.cprofile), "--window", a.window])
                print(f"## {what}, window {a.window}\n")
                print(r["profile"])
            return 0
        res: dict[tuple[str, str], list[dict]] = {}
        for r in range(a.rounds):          # interleaved, the order of the trees alternating
            for what in whats:
                for name, tree in (trees if r % 2 == 0 else trees[::-1]):
                    res.setdefault((name, what), []).append(child(tree, what))
    load = os.getloadavg()[0]
    print(f"Command: `OPENBLAS_NUM_THREADS=1 python bench/bench_pipeline.py --agents {a.agents} --table {a.table} "
          f"--rounds {a.rounds}{f' --before {a.before}' if a.before else ''} --what {a.what} --every {a.every}"
          f"{f' --drop {a.drop:g}' if a.drop else ''}{f' --evict {a.evict:g}' if a.evict else ''}"
          f"{f' --pace {a.pace}' if a.pace else ''}` "
          f"(n = {4 * (a.agents + 1)}; load {load:.1f} after)\n")
    print("CPU per sample, ms: mean over the window (median sample), medians over the rounds\n")
    print(f"| tree | what | answered | served online | first visits (0-{a.first:g}s) | steady ({a.steady:g}-"
          f"{a.steady + a.steady_len:g}s) | departures, re-locks, gaps, gaps retired |")
    print("|---|---|---|---|---|---|---|")
    table = {}
    for (name, what), runs in res.items():
        row = {}
        for w in ("first", "steady"):
            row[w] = (float(np.median([np.sum(r[w]) / r.get(f"{w}_n", len(r[w])) for r in runs])) * 1e3,
                      float(np.median([np.median(r[w]) for r in runs])) * 1e3)
        table[(name, what)] = row
        kal = runs[0].get("kalman", {})
        print(f"| {name} | {what} | {runs[0]['answers']}/{runs[0]['ticks']} | {runs[0].get('online', '-')} "
              f"| {row['first'][0]:.3f} ({row['first'][1]:.3f}) | {row['steady'][0]:.3f} ({row['steady'][1]:.3f}) "
              f"| {', '.join(str(v) for v in kal.values()) or '-'} |")
    for (name, what), runs in res.items():
        if what == "screen":    # the tests alone, timed inside the same samples (the core's noise left out)
            print(f"\n{name}: the tests' CPU per sample (means, medians over the rounds): " + ", ".join(
                f"{w} {np.median([r[f'tests_{w}'] / r[f'{w}_n'] for r in runs]) * 1e3:.3f} ms"
                for w in ("first", "steady")))
    digests = {f"{name} {what}": runs[0]["digest"] for (name, what), runs in res.items() if runs[0].get("digest")}
    if digests:         # the estimates and bounds of every sample (core, screen), by tree
        print("\nsha256 of the estimates and bounds (core, screen; pipeline with --digest: every published "
              "message's bytes and the counters):", ", ".join(f"{k} {v}" for k, v in digests.items()))
    if a.before:
        print("\nthis / before (means):", ", ".join(
            f"{what} {w} {table[('this', what)][w][0] / table[('before', what)][w][0]:.2f}x"
            for what in whats for w in ("first", "steady")))
    if "core" in whats and "pipeline" in whats:
        for name, _ in trees:
            diff = {w: table[(name, "pipeline")][w][0] - table[(name, "core")][w][0] for w in ("first", "steady")}
            print(f"{name}: pipeline - core (means): " + ", ".join(f"{w} {v:.3f} ms" for w, v in diff.items()))
    return 0


if __name__ == "__main__":
    sys.exit(main())
