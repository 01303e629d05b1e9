"""``switchobs_bag generate``: the paper's scenario through camera_sim's model, straight to a bag.

No DDS and no node: the same plant (:class:`switchobs_core.sim.simulate.Plant`, exact), schedule,
noise draws and messages as :class:`switchobs_ros.camera_sim.CameraSimNode` with
``publish_clock: true`` produces, tick by tick, written to a rosbag2 bag as fast as the CPU
allows (about 1 s for 60 s of 100 Hz data). Per tick ``k`` (stamp ``clock_start + k / rate``):

``/clock``, ``/camera/active_channel``, ``/camera/pose``, ``/target/pose``, ``/sim/truth``

(``/camera/active_channel`` after the poses except on a switching tick, as camera_sim sends it:
:meth:`~switchobs_ros.core_config.SensorOutputs.messages`), all with log time = the stamp (what a
recorder on the simulated clock would write). Ticks ``k = 0 .. round(duration * rate)`` as
camera_sim's ``duration``.
"""

from __future__ import annotations

import itertools
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from rosgraph_msgs.msg import Clock as ClockMsg

import msg_bridge as mb
from switchobs_core.exceptions import SwitchobsError
from switchobs_core.model.disturbance import velocity_inputs
from switchobs_core.model.schedule import RandomSchedule, common_rows, parse_schedule
from switchobs_core.ranges import MAX_RATE_HZ, MAX_STAMP_S, OUTPUT_BUDGET_BYTES, check_size
from switchobs_core.sim.disturbed import bang_bang
from switchobs_core.sim.plant import Plant

from ..core_config import DEFAULT_X0, SensorOutputs, load_system_param
from ..params import ConfigError
from .io import BagError, BagOut, type_name

__all__ = ["GenerateConfig", "generate", "scenario_ticks"]

#: Topics a generated bag of the paper's system holds, in camera_sim's per-tick publishing order on a
#: switching tick (another system: ``/clock``, its input topics, ``/sim/truth``).
TOPICS = ("/clock", "/camera/active_channel", "/camera/pose", "/target/pose", "/sim/truth")


@dataclass
class GenerateConfig:
    """What to simulate (camera_sim's parameters of the same names)."""

    system: str = "paper"
    schedule: str = "periodic:2,0.6"
    rate: float = 100.0
    duration: float = 30.0
    noise_std: float = 0.0
    process_noise: float = 0.0
    seed: int = 0
    initial_state: tuple = ()
    clock_start: float = 1.0
    world_frame: str = "map"
    camera_body: str = "camera"
    #: generator only (camera_sim has neither): clip the noise to +-noise_max per row (< 0: no clip),
    #: the bounded noise a declared ``noise.max`` of the estimator covers
    noise_max: float = -1.0
    #: generator only: the plant in extended precision (``Plant(extended=True)``), so that
    #: ``/sim/truth`` is the exact state rounded once: the reference for long checks of the bounds
    extended: bool = False
    #: camera_sim's ``schedule.dead_time``: no target pose in the first seconds after a switch
    dead_time: float = 0.0
    #: camera_sim's ``inputs``: a YAML file whose ``inputs:`` section overrides the system's
    inputs: str = ""
    #: generator only: every velocity state driven by an unknown acceleration of +-accel_max
    #: (:func:`switchobs_core.sim.disturbed.bang_bang`, seeded by ``seed``; the built-in scenarios'
    #: disturbance inputs, :mod:`switchobs_core.model.disturbance`), held over each tick
    accel_max: float = 0.0
    #: generator only: a sensor fault ``(t0, t1, offset)``: ``offset`` added to every output row that
    #: not all channels share (the target poses) at the ticks in ``[t0, t1)`` s (a bias; empty: none)
    bias: tuple = ()
    #: camera_sim's ``channel_type``; the generator's default is the unstamped ``std_msgs/msg/UInt8``
    #: (a recording's order attributes it), ``switchobs_msgs/msg/ActiveChannel`` the stamped one
    channel_type: str = "std_msgs/msg/UInt8"


def _schedule(cfg: GenerateConfig, N: int):
    spec = {"periodic": "periodic:2,0.6", "sequence": "sequence:4,0.5;3,0.6;3,0.6;2,0.4"}.get(cfg.schedule,
                                                                                             cfg.schedule)
    kind, _, rest = spec.partition(":")
    if kind == "random" and len(rest.split(",")) == 2:   # camera_sim: random residence times seeded by `seed`
        if cfg.dead_time:
            raise BagError("--dead-time is for periodic and sequence schedules")
        hmin, hmax = (float(x) for x in rest.split(","))
        return RandomSchedule(N, hmin, hmax, seed=cfg.seed)
    return parse_schedule(spec, N=N, dead_time=cfg.dead_time)


#: Bytes a tick takes in a generated bag (five messages and their index; measured on mcap: 720).
BYTES_PER_TICK = 720


def check_bag_size(cfg: GenerateConfig) -> None:
    """Refuse, before writing, a bag beyond :data:`~switchobs_core.ranges.OUTPUT_BUDGET_BYTES` (what
    the offline tools read) or stamps beyond an int32 of seconds."""
    if not (cfg.rate <= MAX_RATE_HZ):
        raise BagError(f"--rate {cfg.rate:g} Hz is beyond the supported {MAX_RATE_HZ:g} Hz")
    if not (cfg.clock_start + cfg.duration <= MAX_STAMP_S):
        raise BagError(f"--clock-start + --duration = {cfg.clock_start + cfg.duration:g} s is beyond the latest stamp "
                       f"a message carries ({MAX_STAMP_S} s: builtin_interfaces/Time.sec is an int32)")
    ticks = cfg.duration * cfg.rate + 1
    check_size(ticks, BYTES_PER_TICK, f"a bag of {ticks:.3g} ticks ({cfg.duration:g} s at {cfg.rate:g} Hz)",
               "lower --duration or --rate", budget=OUTPUT_BUDGET_BYTES, exc=BagError)


def scenario_ticks(cfg: GenerateConfig) -> Iterator[tuple[int, list[tuple[str, object]]]]:
    """Yield ``(stamp_ns, [(topic, rclpy message), ...])`` per tick, as camera_sim publishes them."""
    try:
        sys_ = load_system_param(cfg.system)
        schedule = _schedule(cfg, sys_.N)
        try:
            specs = mb.load_inputs(cfg.system, sys_, camera_body=cfg.camera_body, override=cfg.inputs)
        except mb.SpecError as err:
            raise BagError(f"input specification: {err}") from None
        outputs = SensorOutputs(specs)
        if not cfg.rate > 0 or not cfg.duration >= 0 or not cfg.clock_start > 0:
            raise BagError(f"need rate > 0, duration >= 0, clock_start > 0; got {cfg.rate}, {cfg.duration}, "
                           f"{cfg.clock_start}")
        check_bag_size(cfg)
        x0 = cfg.initial_state or (DEFAULT_X0 if sys_.n == len(DEFAULT_X0) else (0.0,) * sys_.n)
        if len(x0) != sys_.n:
            raise BagError(f"initial state has {len(x0)} values; the system has n = {sys_.n}")
        B_w = velocity_inputs(sys_) if cfg.accel_max > 0 else None
        if B_w is not None and not B_w.shape[1]:
            raise BagError(f"--accel-max: the system {cfg.system} has no velocity state to accelerate")
        plant = Plant(sys_, np.array(x0, dtype=float), seed=cfg.seed, process_noise=cfg.process_noise,
                      extended=cfg.extended, B_w=B_w)
        accel = None if B_w is None else bang_bang(np.full(B_w.shape[1], cfg.accel_max), cfg.rate, cfg.seed + 2)
    except (SwitchobsError, ConfigError) as err:
        raise BagError(str(err)) from None
    rng = np.random.default_rng(cfg.seed + 1)
    if cfg.bias and len(cfg.bias) != 3:
        raise BagError(f"bias needs three values T0,T1,OFFSET; got {cfg.bias}")
    shared = set(common_rows(sys_.C))
    labels = tuple(sys_.state_labels)
    period_ns = round(1e9 / cfg.rate)
    epoch_ns = round(cfg.clock_start * 1e9)
    k_end = round(cfg.duration * cfg.rate)
    switch = (0, 0)         # (channel, its switching instant: the first tick stamp on it)
    stamped = cfg.channel_type == "switchobs_msgs/msg/ActiveChannel"
    for k in range(k_end + 1):
        # camera_sim.CameraSimNode.publish_tick, step for step
        t = k * period_ns * 1e-9
        stamp_ns = epoch_ns + k * period_ns
        plant.advance(t, w=None if accel is None or not k else accel((k - 1) * period_ns * 1e-9))
        rho = int(schedule.channel_at(t))
        switching = rho != switch[0]
        if switching:
            switch = (rho, stamp_ns)
        y = plant.measure(rho, noise_std=0.0)
        if cfg.noise_std > 0:
            v = cfg.noise_std * rng.standard_normal(y.shape)
            y = y + (np.clip(v, -cfg.noise_max, cfg.noise_max) if cfg.noise_max >= 0 else v)
        if cfg.bias and cfg.bias[0] <= t < cfg.bias[1]:
            y = y + np.array([0.0 if j in shared else float(cfg.bias[2]) for j in range(y.size)])
        # the system's input topics, as camera_sim publishes them (no target pose while the camera turns)
        msgs = [("/clock", ClockMsg(clock=mb.ns_to_stamp(stamp_ns)))]
        msgs += [("/" + topic, m) for topic, m in outputs.messages(rho, y, stamp_ns, cfg.world_frame,
                                                                  schedule.blind_at(t), switch[1] if stamped else None,
                                                                  switching=switching)]
        msgs.append(("/sim/truth", mb.labelled_array(plant.x, labels, stamp_ns)))
        yield stamp_ns, msgs


def generate(out: str | Path, cfg: GenerateConfig, storage: str = "mcap", progress: bool | None = False) -> dict:
    """Write the scenario's input bag to ``out``; return a summary (ticks, messages, span).
    ``progress``: a bar of the ticks on stderr (None: on a terminal)."""
    from rclpy.serialization import serialize_message
    from tqdm import tqdm

    from msg_bridge.cdr_padding import zero_padding

    ticks = 0
    first = last = None
    it = scenario_ticks(cfg)
    head = next(it, None)       # every check of cfg runs here, before the bag folder is created
    added: set[str] = set()
    total = round(cfg.duration * cfg.rate) + 1
    with BagOut(out, storage) as bag:
        for stamp_ns, msgs in tqdm(itertools.chain([head] if head is not None else [], it), total=total,
                                   disable=None if progress is None else not progress, leave=False, unit="tick",
                                   desc="generate"):
            for topic, msg in msgs:
                if topic not in added:          # the system's topics, each with its message type
                    bag.add(topic, type_name(type(msg)))
                    added.add(topic)
                bag.write(topic, stamp_ns, bytes(zero_padding(msg, serialize_message(msg))))   # no heap bytes
            ticks += 1
            first = stamp_ns if first is None else first
            last = stamp_ns
        count = bag.count
    return {"path": str(out), "storage": storage, "ticks": ticks, "messages": count,
            "start_ns": first, "end_ns": last}
