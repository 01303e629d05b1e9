"""``switchobs_bag``: rosbag2 bags through the switchobs estimator, live and offline.

::

    switchobs_bag generate OUT [--schedule periodic:2,0.6] [--rate 100] [--duration 30] [--noise 0]
                               [--seed 0] [--storage mcap|sqlite3]
    switchobs_bag record OUT [--topics T ...] [--duration S] [--count N] [--storage ...] [--ros-args ...]
    switchobs_bag play BAG [--rate 1] [--loop | --loops N] [--no-clock] [--wait-node estimator] [--ros-args ...]
    switchobs_bag estimate BAG -o OUT [--csv F] [--params-file F ...] [-p name:=value ...] [--gain-table F]
    switchobs_bag report BAG [-o report.png] [--summary summary.md]
    switchobs_bag info BAG

A bad bag (missing, truncated, a missing topic, a wrong type) or a bad option gives one line on
stderr, ``switchobs_bag: error: ...``, and exit code 2; a timeout waiting for subscribers or
publishers exits 3.
"""

from __future__ import annotations

import argparse
import json
import signal
import sys
from pathlib import Path

__all__ = ["main"]

PROG = "switchobs_bag"


def _split_ros_args(argv):
    """``argv`` before ``--ros-args``, and the ROS arguments (from ``--ros-args`` on)."""
    if "--ros-args" in argv:
        i = argv.index("--ros-args")
        return argv[:i], argv[i:]
    return argv, []


def _parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog=PROG, description="rosbag2 bags through the switchobs estimator.")
    sub = ap.add_subparsers(dest="cmd", required=True)

    g = sub.add_parser("generate", help="the paper's scenario (camera_sim's model) straight to a bag, no DDS")
    g.add_argument("out", help="new bag folder")
    g.add_argument("--system", default="paper")
    g.add_argument("--schedule", default="periodic",
                   help="periodic (2 s, 0.6), sequence (the paper's), or periodic:TAU,S | periodic-h:H1,..,HN | "
                        "sequence:T,S;T,S;... | random:HMIN,HMAX[,SEED] (default: periodic)")
    g.add_argument("--rate", type=float, default=100.0, help="measurement rate in Hz (default 100)")
    g.add_argument("--duration", type=float, default=30.0, help="simulated seconds (default 30)")
    g.add_argument("--noise", type=float, default=0.0, help="measurement noise std (m)")
    g.add_argument("--process-noise", type=float, default=0.0)
    g.add_argument("--seed", type=int, default=0)
    g.add_argument("--initial-state", default="", help="comma-separated x(0) (default: camera_sim's scene)")
    g.add_argument("--clock-start", type=float, default=1.0, help="stamp of tick 0 in seconds (default 1.0)")
    g.add_argument("--storage", choices=["mcap", "sqlite3"], default="mcap")

    r = sub.add_parser("record", help="subscribe to topics and write a bag (receive time on the node clock)")
    r.add_argument("out", help="new bag folder")
    r.add_argument("--topics", nargs="+", default=[], help="absolute topic names (default: the estimator's "
                   "inputs and outputs, /sim/truth, /diagnostics)")
    r.add_argument("--duration", type=float, default=0.0, help="stop after this many wall seconds")
    r.add_argument("--count", type=int, default=0, help="stop after this many messages")
    r.add_argument("--storage", choices=["mcap", "sqlite3"], default="mcap")
    r.add_argument("--wait-publishers", nargs="*", default=None, metavar="TOPIC",
                   help="before recording, wait for a publisher on these topics (none given: on every topic)")
    r.add_argument("--wait-timeout", type=float, default=30.0)

    p = sub.add_parser("play", help="publish a bag live, with /clock")
    p.add_argument("bag")
    p.add_argument("--rate", type=float, default=1.0, help="speed factor (default 1: recorded timing)")
    p.add_argument("--loop", action="store_true", help="play again and again until stopped")
    p.add_argument("--loops", type=int, default=1, help="number of passes (default 1)")
    p.add_argument("--no-clock", action="store_true", help="do not publish /clock (play the bag's own, if any)")
    p.add_argument("--topics", nargs="+", default=[], help="only these topics")
    p.add_argument("--all-topics", action="store_true",
                   help="also the estimator's outputs and /diagnostics (skipped by default)")
    p.add_argument("--no-wait", action="store_true", help="start at once, without waiting for subscribers")
    p.add_argument("--wait-node", default="estimator",
                   help="wait until this node subscribes to the inputs and /clock ('' = any node)")
    p.add_argument("--wait-timeout", type=float, default=30.0)
    p.add_argument("--settle", type=float, default=0.5, help="seconds between the match and the first message")
    p.add_argument("--channel-lead", type=float, default=0.005,
                   help="seconds to wait after a channel change before the next message (default 0.005)")
    p.add_argument("--loop-pause", type=float, default=0.2, help="seconds after the /clock jump of a new pass")

    e = sub.add_parser("estimate", help="run the estimator pipeline over a bag, offline; write a bag and CSV")
    e.add_argument("bag")
    e.add_argument("-o", "--out", help="new bag folder for the estimates (and the copied inputs)")
    e.add_argument("--csv", help="CSV file of the estimates")
    e.add_argument("--storage", choices=["mcap", "sqlite3"], default=None, help="default: the input bag's")
    e.add_argument("--estimates-only", action="store_true", help="do not copy the input topics")
    e.add_argument("--params-file", action="append", default=[], help="estimator params file (ROS 2 YAML)")
    e.add_argument("-p", "--param", action="append", default=[], metavar="NAME:=VALUE")
    e.add_argument("--gain-table", help="shortcut for -p gain_table:=FILE")
    e.add_argument("--node", default="/estimator", help="namespace of the output topics (default /estimator)")
    e.add_argument("--json", action="store_true")

    rp = sub.add_parser("report", help="plots and a summary from a bag with estimates (and truth)")
    rp.add_argument("bag")
    rp.add_argument("-o", "--out", default="report.png", help="PNG file (default report.png)")
    rp.add_argument("--summary", help="also write the summary (Markdown) to this file")
    rp.add_argument("--node", default="/estimator")
    rp.add_argument("--title", default="")
    rp.add_argument("--json", action="store_true")

    i = sub.add_parser("info", help="topics, types, counts and span of a bag")
    i.add_argument("bag")
    return ap


class _StopFlag:
    """SIGINT/SIGTERM set a flag; the loops check it and close the bag cleanly."""

    def __init__(self):
        self.stop = False
        for s in (signal.SIGINT, signal.SIGTERM):
            signal.signal(s, self._handler)

    def _handler(self, *_):
        self.stop = True

    def __call__(self) -> bool:
        return self.stop


def _ros_node(name: str, ros_argv):
    import rclpy
    from rclpy.signals import SignalHandlerOptions

    rclpy.init(args=[PROG, *ros_argv], signal_handler_options=SignalHandlerOptions.NO)
    return rclpy.create_node(name)


def _params(a) -> dict:
    import yaml

    from .estimate import estimator_params
    over = {}
    for item in a.param:
        name, sep, val = item.partition(":=")
        if not sep:
            raise ValueError(f"-p {item}: expected NAME:=VALUE")
        over[name] = yaml.safe_load(val) if val != "" else ""
    if a.gain_table:
        over["gain_table"] = a.gain_table
    return estimator_params(a.params_file, over)


def _run(a, ros_argv) -> int:
    from . import io

    if a.cmd == "generate":
        from .generate import GenerateConfig, generate
        x0 = tuple(float(v) for v in a.initial_state.split(",")) if a.initial_state else ()
        cfg = GenerateConfig(schedule=a.schedule, rate=a.rate, duration=a.duration, noise_std=a.noise,
                             process_noise=a.process_noise, seed=a.seed, initial_state=x0, system=a.system,
                             clock_start=a.clock_start)
        res = generate(a.out, cfg, a.storage)
        print(f"wrote {res['path']} ({res['storage']}): {res['ticks']} ticks, {res['messages']} messages, "
              f"{(res['end_ns'] - res['start_ns']) * 1e-9:.2f} s")
        return 0
    if a.cmd == "info":
        with io.BagIn(a.bag) as bag:
            msgs = bag.messages()
            span = (msgs[-1].log_ns - msgs[0].log_ns) * 1e-9 if msgs else 0.0
            print(f"{bag.path} ({bag.storage}): {bag.message_count} messages, {span:.3f} s")
            for t, ty in sorted(bag.topics.items()):
                print(f"  {t:36s} {ty:40s} {bag.counts[t]}")
        return 0
    if a.cmd == "estimate":
        from .estimate import estimate
        if not a.out and not a.csv:
            raise ValueError("give -o OUT (a new bag) and/or --csv FILE")
        res = estimate(a.bag, _params(a), out=a.out, csv=a.csv, storage=a.storage, inputs=not a.estimates_only,
                       node=a.node)
        rate = res.messages_in / res.seconds if res.seconds > 0 else float("inf")
        info = {"estimates": int(res.stamps.size), "messages": res.messages_in, "inputs": res.inputs,
                "seconds": res.seconds, "messages_per_s": rate, "updates": res.updates,
                "partial_updates": res.partial_updates, "rejected": res.rejected, "out": res.out, "csv": res.csv}
        if a.json:
            print(json.dumps(info))
        else:
            print(f"{res.stamps.size} estimates from {res.messages_in} messages in {res.seconds:.3f} s "
                  f"({rate:,.0f} messages/s); partial updates {res.partial_updates}; rejected "
                  f"{sum(res.rejected.values())} {res.rejected or ''}".rstrip())
            for what in ("out", "csv"):
                if info[what]:
                    print(f"wrote {info[what]}")
        return 0
    if a.cmd == "report":
        from .report import load_report, plot_report, summary_table
        rep = load_report(a.bag, a.node)
        plot_report(rep, a.out, a.title)
        text = summary_table(rep)
        if a.summary:
            Path(a.summary).write_text(text + "\n")
        if a.json:
            print(json.dumps({"passes": [{"estimates": len(p.t), "initial_error": p.e_first, "final_error": p.e_final,
                                          "final_exact_bound": float(p.exact[-1]),
                                          "final_paper_bound": float(p.paper[-1]),
                                          "contraction": p.contraction} for p in rep.passes],
                              "rejected": rep.rejected, "png": a.out}))
        else:
            print(text)
            print(f"wrote {a.out}" + (f" and {a.summary}" if a.summary else ""))
        return 0
    if a.cmd in ("record", "play"):
        stop = _StopFlag()
        import rclpy
        node = _ros_node(f"switchobs_bag_{a.cmd}", ros_argv)
        try:
            if a.cmd == "record":
                from .record import RecordConfig, record
                waited = None if a.wait_publishers is None else tuple(a.wait_publishers)
                cfg = RecordConfig(topics=tuple(a.topics), storage=a.storage, duration=a.duration, count=a.count,
                                   wait_publishers=waited, wait_timeout=a.wait_timeout)
                res = record(a.out, cfg, node=node, log=_log, should_stop=stop)
                print(f"wrote {res['path']}: {res['messages']} messages"
                      + (f" ({res['dropped_before_clock']} dropped before the first /clock)"
                         if res["dropped_before_clock"] else ""), flush=True)
            else:
                from .play import PlayConfig, play
                cfg = PlayConfig(rate=a.rate, loops=0 if a.loop else a.loops, clock=not a.no_clock,
                                 topics=tuple(a.topics), all_topics=a.all_topics, wait=not a.no_wait,
                                 wait_node=a.wait_node, wait_timeout=a.wait_timeout, settle=a.settle,
                                 channel_lead=a.channel_lead, loop_pause=a.loop_pause)
                res = play(a.bag, cfg, node=node, log=_log, should_stop=stop)
                print(f"played {res['published']} messages in {res['passes']} pass(es); "
                      f"latest message {res['max_late_s'] * 1e3:.1f} ms behind its time", flush=True)
        finally:
            node.destroy_node()
            rclpy.try_shutdown()
        return 0
    raise ValueError(f"unknown command {a.cmd}")


def _log(text: str) -> None:
    print(f"{PROG}: {text}", flush=True)


def main(argv=None) -> int:
    from switchobs_core.threads import single_threaded_blas

    single_threaded_blas()
    argv = list(sys.argv[1:] if argv is None else argv)
    own, ros_argv = _split_ros_args(argv)
    a = _parser().parse_args(own)
    from switchobs_core.exceptions import SwitchobsError
    from switchobs_ros.params import ConfigError
    try:
        return _run(a, ros_argv)
    except TimeoutError as err:
        print(f"{PROG}: error: {_one_line(err)}", file=sys.stderr)
        return 3
    except (SwitchobsError, ConfigError, ValueError, OSError) as err:
        print(f"{PROG}: error: {_one_line(err)}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130


def _one_line(err: BaseException) -> str:
    return " ".join(str(err).split()) or type(err).__name__


if __name__ == "__main__":
    sys.exit(main())
