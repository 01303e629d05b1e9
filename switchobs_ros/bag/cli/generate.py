"""``switchobs_bag generate``: the paper's scenario (camera_sim's model) straight to a bag, no DDS."""

from __future__ import annotations

import argparse

__all__ = ["register", "run"]


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("generate", help="the paper's scenario (camera_sim's model) straight to a bag, no DDS")
    p.add_argument("out", help="new bag folder")
    p.add_argument("--system", default="paper")
    p.add_argument("--schedule", default="periodic",
                   help="periodic (2 s, 0.6), sequence (the paper's), or periodic:TAU,S | periodic-h:H1,..,HN | "
                        "sequence:T,S;T,S;... | random:HMIN,HMAX[,SEED] (default: periodic)")
    p.add_argument("--rate", type=float, default=100.0, help="measurement rate in Hz (default 100)")
    p.add_argument("--duration", type=float, default=30.0, help="simulated seconds (default 30)")
    p.add_argument("--dead-time", type=float, default=0.0, metavar="S",
                   help="seconds after each switch without a target pose, while the camera turns (default 0)")
    p.add_argument("--noise", type=float, default=0.0, help="measurement noise std (m)")
    p.add_argument("--process-noise", type=float, default=0.0)
    p.add_argument("--noise-max", type=float, default=-1.0,
                   help="clip the measurement noise to +-NOISE_MAX per row (bounded noise; default: no clip)")
    p.add_argument("--accel-max", type=float, default=0.0, metavar="A",
                   help="drive every velocity state with an unknown acceleration of +-A (bang-bang, signs switching "
                        "at random, seeded; the disturbance a declared disturbance.max >= A covers; default 0)")
    p.add_argument("--extended-truth", action="store_true",
                   help="simulate the plant in extended precision: /sim/truth is the exact state rounded once "
                        "(the reference for long checks of the exact bound)")
    p.add_argument("--bias", default="", metavar="T0,T1,OFFSET",
                   help="a sensor fault: OFFSET (m) added to the target poses (the rows not all channels share) "
                        "from T0 to T1 s (default: none)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--initial-state", default="", help="comma-separated x(0) (default: camera_sim's scene)")
    p.add_argument("--clock-start", type=float, default=1.0, help="stamp of tick 0 in seconds (default 1.0)")
    p.add_argument("--storage", choices=["mcap", "sqlite3"], default="mcap")
    p.add_argument("--progress", action=argparse.BooleanOptionalAction, default=None,
                   help="progress bar on stderr (default: on a terminal)")

    p.set_defaults(func=run)


def run(a: argparse.Namespace, ros_argv: list[str]) -> int:
    # the simulator: imported by this command only
    from ..generate import GenerateConfig, generate

    x0 = tuple(float(v) for v in a.initial_state.split(",")) if a.initial_state else ()
    bias = tuple(float(v) for v in a.bias.split(",")) if a.bias else ()
    cfg = GenerateConfig(schedule=a.schedule, rate=a.rate, duration=a.duration, noise_std=a.noise,
                         process_noise=a.process_noise, seed=a.seed, noise_max=a.noise_max,
                         extended=a.extended_truth, initial_state=x0, system=a.system,
                         clock_start=a.clock_start, dead_time=a.dead_time, accel_max=a.accel_max,
                         bias=bias)
    res = generate(a.out, cfg, a.storage, progress=a.progress)
    print(f"wrote {res['path']} ({res['storage']}): {res['ticks']} ticks, {res['messages']} messages, "
          f"{(res['end_ns'] - res['start_ns']) * 1e-9:.2f} s")
    return 0
