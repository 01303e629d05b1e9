"""camera_sim: the paper's camera and agents, simulated exactly, published as the camera would.

``ros2 run switchobs_ros camera_sim --ros-args --params-file config/camera_sim.yaml``

The plant is :class:`switchobs_core.sim.simulate.Plant` (exact propagation with ``expm``) of the
configured system (default: the paper's camera + 2 agents, D_c = diag(0, 0), D_1 =
diag(0, 0.2), D_2 = diag(0, 0.1)). The camera switches between agents by a schedule of
:mod:`switchobs_core.model.schedule` (periodic or a sequence of cycles, or random within A2's
box). At every tick ``k`` (``rate`` Hz) it publishes, in this order:

1. ``/clock`` (only with ``publish_clock``),
2. ``camera/active_channel`` (``switchobs_msgs/ActiveChannel``: the channel rho(t_k) stamped with
   its switching instant, the first tick on it; or std_msgs/UInt8 with ``channel_type``; reliable,
   transient local),
3. ``camera/pose`` and ``target/pose`` (PoseStamped, same stamp ``t_k``, sensor-data QoS; no
   ``target/pose`` in the first ``schedule.dead_time`` seconds after a switch, while the camera turns),
4. ``sim/truth`` (the true state x(t_k), a labelled Float64MultiArray stamped t_k; reliable).

The stamped channel message comes first only on a switching tick. On every other tick it comes after
the poses (between 3 and 4). There it is a heartbeat sent after the tick's samples: it proves their
channel as it arrives (:mod:`switchobs_ros.switching`: a channel message sent ``2 x
clock_tolerance_ms`` after a sample). With exact stamps (``clock_tolerance_ms: 0``, the estimator's
default) the estimator so answers every sample of a residence at once, including the last part
beyond ``switch_horizon``, which would otherwise wait one tick for the next heartbeat; with a
tolerance, that part still waits for the first heartbeat sent ``2 x`` the tolerance later. A
``std_msgs/UInt8`` channel takes the same places
(:meth:`~switchobs_ros.core_config.SensorOutputs.messages`); without a switching instant it has no
horizon, so only a switching tick's poses wait, for the next tick's message.

``stamp_offset_ms`` shifts the stamps of the camera's own pose and of the switching instants (a
camera computer whose clock runs that far ahead of the targets'); ``channel_last`` publishes the
channel message after the poses (the first pose of a new channel sent before it).

Time: tick k is at plant time ``k / rate`` and stamp ``epoch + k / rate``. Without
``publish_clock`` the epoch is the time the first timer call after start was due on the node
clock (the timer's own grid: a call late by less than a period publishes the next tick, a call
later than that skips the ticks it missed) and ticks follow the node clock (so ``use_sim_time``
on camera_sim works as for any node). With ``publish_clock`` camera_sim
*is* the clock: it publishes ``/clock`` itself, starting at ``clock_start``, and runs
``time_scale`` times faster than the wall clock; run the estimator with ``use_sim_time:=true``.
"""

from __future__ import annotations

import math
import sys
import time
from dataclasses import dataclass

import numpy as np
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rosgraph_msgs.msg import Clock as ClockMsg
from std_msgs.msg import Float64MultiArray, UInt8
from switchobs_msgs.msg import ActiveChannel

import msg_bridge as mb
from switchobs_core.exceptions import SwitchobsError
from switchobs_core.model.disturbance import velocity_inputs
from switchobs_core.model.schedule import PeriodicSchedule, RandomSchedule, SequenceSchedule, common_rows
from switchobs_core.ranges import MAX_DURATION_S, MAX_RATE_HZ, MAX_STAMP_S
from switchobs_core.sim.disturbed import bang_bang
from switchobs_core.sim.plant import Plant

from . import qos
from .core_config import DEFAULT_X0, SensorOutputs, cycles_from_params, load_system_param
from .params import ConfigError, Param, declare_all
from .runner import run_node

__all__ = ["CameraSimNode", "PARAMS", "DEFAULT_X0", "main"]


PARAMS = [
    Param("system", "paper", "The simulated system: a built-in scenario name or a system YAML path (published "
          "by its input specification, the `inputs:` section; the paper interface for camera/target systems)."),
    Param("rate", 100.0, "Measurement rate in Hz (ticks of plant time)."),
    Param("schedule.mode", "periodic", "periodic (one cycle), sequence (cycles repeated in order) or random "
          "(residence times uniform in [schedule.h_min, schedule.h_max], seeded)."),
    Param("schedule.tau", (2.0,), "Cycle lengths tau_k in seconds (two-channel systems).", float),
    Param("schedule.s", (0.6,), "Duty fractions s_k, one per schedule.tau entry.", float),
    Param("schedule.h", (), "N-channel cycles: N active times per cycle, concatenated (overrides tau/s).", float),
    Param("schedule.dead_time", 0.0, "Seconds after each switch while the camera turns: camera/pose only, no "
          "target/pose (periodic and sequence modes)."),
    Param("schedule.h_min", 0.0, "random mode: shortest residence time (s)."),
    Param("schedule.h_max", 0.0, "random mode: longest residence time (s)."),
    Param("initial_state", (), "True initial state x(0), n values (empty: the default scene for the paper "
          "model, zeros otherwise).", float),
    Param("noise_std", 0.0, "Standard deviation of the measurement noise added to every position (m)."),
    Param("process_noise", 0.0, "Process noise intensity q (Qc = q^2 I) of the plant."),
    Param("accel_max", 0.0, "Drive every velocity state with an unknown acceleration of +-accel_max (m/s^2; "
          "bang-bang, signs switching at random, seeded by seed): bodies that manoeuvre within a declared "
          "disturbance.max. 0: none."),
    Param("bias.offset_m", 0.0, "A sensor fault: this offset (m) added to every target pose (the output rows not "
          "every channel shares; the camera's own pose is untouched) published in [bias.start_s, bias.start_s + "
          "bias.duration_s) of simulated time: a bias beyond a declared noise.max, which the estimator must "
          "detect and recover from. 0: none."),
    Param("bias.start_s", 0.0, "Simulated time (s, >= 0) at which the bias begins."),
    Param("bias.duration_s", 0.0, "Seconds the bias lasts (> 0 when bias.offset_m is not 0)."),
    Param("bias.channel", 0, "The channel whose samples carry the bias (1..N); 0: every channel."),
    Param("seed", 0, "Seed of all noise draws."),
    Param("world_frame", "map", "header.frame_id of the published poses."),
    Param("camera_body", "camera", "Name of the camera body in the system's output labels."),
    Param("inputs", "", "Path of a YAML file with an `inputs:` section overriding the system's (as the "
          "estimator's parameter): the topics, types and fields camera_sim publishes."),
    Param("duration", 0.0, "Simulated seconds to run, then exit 0 (> 0; 0, the default, explicitly means: until "
          "stopped; negative values are refused)."),
    Param("publish_clock", False, "Publish /clock and run on that simulated clock (see time_scale)."),
    Param("time_scale", 1.0, "With publish_clock: simulated seconds per wall-clock second."),
    Param("clock_start", 1.0, "With publish_clock: the simulated clock's value at tick 0 (s, > 0)."),
    Param("channel_type", "switchobs_msgs/msg/ActiveChannel", "The channel message: switchobs_msgs/msg/ActiveChannel "
          "(stamped with the switching instant) or std_msgs/msg/UInt8 (the channel alone)."),
    Param("stamp_offset_ms", 0.0, "Milliseconds added to the stamps of the camera's own pose and of the switching "
          "instants: a camera clock ahead of the targets' (a test of clocks across computers)."),
    Param("channel_last", False, "Publish the channel message after the tick's poses on every tick, switching "
          "ticks included (the first pose of a new channel is then sent before its channel message). Default: "
          "the channel message after the poses except on a switching tick (module docstring)."),
    Param("wait_for_subscribers", 0, "Before tick 0, wait until target/pose has this many subscribers."),
    Param("wait_for_truth_subscribers", 0, "Before tick 0, wait until sim/truth has this many subscribers."),
    Param("stamp_at_send", False, "Stamp each tick with the node clock when it is sent, as a sensor stamping "
          "with its own clock does (the timer's jitter in every stamp), the plant advanced to that stamp; "
          "default: the tick's nominal time epoch + k / rate. Not with publish_clock."),
]


def _check_ranges(cfg: dict) -> None:
    """The range policy (:mod:`switchobs_core.ranges`) for camera_sim's numbers: the tick period
    ``1 / (rate x time_scale)`` is an rclpy timer (at least 1 us, at most MAX_DURATION_S), the
    stamps (``clock_start`` + simulated time) fit ``builtin_interfaces/Time.sec`` (an int32)."""
    rate = cfg["rate"] * (cfg["time_scale"] if cfg["publish_clock"] else 1.0)
    if not 1.0 / MAX_DURATION_S <= rate <= MAX_RATE_HZ:
        raise ConfigError(f"parameters 'rate' x 'time_scale' = {rate:g} Hz must be in [{1 / MAX_DURATION_S:g}, "
                          f"{MAX_RATE_HZ:g}] (the tick timer's period)")
    for name in ("clock_start", "duration", "time_scale"):
        if cfg[name] > MAX_STAMP_S:
            raise ConfigError(f"parameter '{name}' = {cfg[name]:g} is beyond {MAX_STAMP_S} (stamps carry an int32 of "
                              "seconds)")


@dataclass(frozen=True)
class SensorBias:
    """``offset`` (m) added to the output rows not in ``shared`` (the rows every channel measures:
    the camera's own pose) of the samples of ``channel`` (0: every channel) at plant times in
    ``[t0, t1)``."""

    offset: float
    shared: frozenset
    t0: float
    t1: float
    channel: int

    def add(self, t: float, channel: int, y: np.ndarray) -> np.ndarray:
        """``y`` with the bias when it applies at ``t`` to ``channel``."""
        if not (self.t0 <= t < self.t1 and self.channel in (0, channel)):
            return y
        return y + np.array([0.0 if j in self.shared else self.offset for j in range(y.size)])


def _bias(cfg: dict, sys_) -> SensorBias | None:
    """The ``bias.*`` parameters, checked (None: ``bias.offset_m`` is 0)."""
    off, t0, dur, ch = cfg["bias.offset_m"], cfg["bias.start_s"], cfg["bias.duration_s"], cfg["bias.channel"]
    if not math.isfinite(off) or abs(off) > MAX_STAMP_S:
        raise ConfigError(f"parameter 'bias.offset_m' must be a finite number of metres; got {off}")
    if not (math.isfinite(t0) and 0.0 <= t0 <= MAX_STAMP_S):
        raise ConfigError(f"parameter 'bias.start_s' must be a finite time >= 0; got {t0}")
    if not (math.isfinite(dur) and 0.0 <= dur <= MAX_STAMP_S) or (off != 0.0 and dur == 0.0):
        raise ConfigError(f"parameter 'bias.duration_s' must be a finite number of seconds, > 0 with a bias; got {dur}")
    if not 0 <= ch <= sys_.N:
        raise ConfigError(f"parameter 'bias.channel' must be 0 (every channel) or a channel 1..{sys_.N}; got {ch}")
    if off == 0.0:
        return None
    shared = frozenset(common_rows(sys_.C))
    if all(set(range(Ci.shape[0])) <= shared for Ci in sys_.C):
        raise ConfigError(f"parameter 'bias.offset_m': every output row of {sys_.name} is shared by all channels "
                          "(no target pose to bias)")
    return SensorBias(float(off), shared, float(t0), float(t0) + float(dur), int(ch))


class CameraSimNode(Node):
    """Publishes the simulated camera measurements and the truth."""

    def __init__(self, **kwargs):
        super().__init__("camera_sim", **kwargs)
        cfg = declare_all(self, PARAMS)
        self.cfg = cfg
        self.exit_code = 0
        self.system = sys_ = load_system_param(cfg["system"])
        mode = cfg["schedule.mode"]
        try:
            if mode == "random":
                if cfg["schedule.dead_time"]:
                    raise ConfigError("parameter 'schedule.dead_time' is for periodic and sequence modes")
                self.schedule = RandomSchedule(sys_.N, cfg["schedule.h_min"], cfg["schedule.h_max"], seed=cfg["seed"])
            elif mode in ("periodic", "sequence"):
                cycles = cycles_from_params(mode, cfg["schedule.tau"], cfg["schedule.s"], cfg["schedule.h"], sys_.N,
                                            cfg["schedule.dead_time"])
                self.schedule = PeriodicSchedule(cycles[0]) if mode == "periodic" else SequenceSchedule(cycles)
            else:
                raise ConfigError(f"parameter 'schedule.mode' must be periodic, sequence or random; got '{mode}'")
        except SwitchobsError as err:
            raise ConfigError(f"schedule: {err}") from None
        for name, lo in (("rate", "> 0"), ("duration", ">= 0"), ("noise_std", ">= 0"), ("process_noise", ">= 0"),
                         ("accel_max", ">= 0"), ("time_scale", "> 0"), ("clock_start", "> 0")):
            v = cfg[name]
            ok = math.isfinite(v) and (v > 0 if lo == "> 0" else v >= 0)
            if not ok:
                raise ConfigError(f"parameter '{name}' must be a finite number {lo}; got {v}"
                                  + (" (0 runs until stopped)" if name == "duration" else ""))
        _check_ranges(cfg)
        self.bias = _bias(cfg, sys_)
        if not cfg["world_frame"]:
            raise ConfigError("parameter 'world_frame' must not be empty")
        x0 = cfg["initial_state"]
        if not x0:
            x0 = DEFAULT_X0 if sys_.n == len(DEFAULT_X0) else (0.0,) * sys_.n
        if len(x0) != sys_.n:
            raise ConfigError(f"parameter 'initial_state' has {len(x0)} values; the system has n = {sys_.n}")
        try:
            B_w = velocity_inputs(sys_) if cfg["accel_max"] > 0 else None
            if B_w is not None and not B_w.shape[1]:
                raise ConfigError(f"parameter 'accel_max': the system {sys_.name} has no velocity state to accelerate")
            self.plant = Plant(sys_, np.array(x0, dtype=float), seed=cfg["seed"], process_noise=cfg["process_noise"],
                               B_w=B_w)
            self.accel = (None if B_w is None else
                          bang_bang(np.full(B_w.shape[1], cfg["accel_max"]), cfg["rate"], cfg["seed"] + 2))
        except SwitchobsError as err:
            raise ConfigError(f"plant: {err}") from None
        try:
            self.specs = mb.load_inputs(cfg["system"], sys_, camera_body=cfg["camera_body"], override=cfg["inputs"])
        except mb.SpecError as err:
            raise ConfigError(f"input specification: {err}") from None
        self.outputs = SensorOutputs(self.specs)
        self.rng = np.random.default_rng(cfg["seed"] + 1)
        self.labels = tuple(sys_.state_labels)
        self.frame = cfg["world_frame"]
        self.period_ns = round(1e9 / cfg["rate"])
        self.k = -1
        self.started = False
        self.epoch_ns = 0
        self.last_stamp_ns = -1
        self.t_wait = time.monotonic()
        self.k_end = round(cfg["duration"] * cfg["rate"]) if cfg["duration"] > 0 else None

        self.pub_clock = self.create_publisher(ClockMsg, "/clock", qos.CLOCK) if cfg["publish_clock"] else None
        # one publisher per input topic of the system's specification (the paper's: the channel,
        # camera/pose, target/pose); the channel first
        self.pubs = {}
        if cfg["channel_type"] not in ("switchobs_msgs/msg/ActiveChannel", "std_msgs/msg/UInt8"):
            raise ConfigError("parameter 'channel_type' must be switchobs_msgs/msg/ActiveChannel or "
                              f"std_msgs/msg/UInt8; got '{cfg['channel_type']}'")
        self.stamped = cfg["channel_type"] == "switchobs_msgs/msg/ActiveChannel"
        if not math.isfinite(cfg["stamp_offset_ms"]) or abs(cfg["stamp_offset_ms"]) > 1000.0:
            raise ConfigError(f"parameter 'stamp_offset_ms' must be within [-1000, 1000]; got {cfg['stamp_offset_ms']}")
        self.offset_ns = round(cfg["stamp_offset_ms"] * 1e6)
        self.switch = (0, 0)        # (channel, its switching instant: the first tick stamp on it)
        if self.specs.channel_topic:
            self.pubs[self.specs.channel_topic] = self.create_publisher(ActiveChannel if self.stamped else UInt8,
                                                                        self.specs.channel_topic,
                                                                        qos.channel_pub(cfg["rate"]))
        for src in self.specs.sources:
            self.pubs[src.topic] = self.create_publisher(mb.message_class(src.type), src.topic, qos.SENSOR)
        self.pub_target = self.pubs[next((s.topic for s in self.specs.sources if not s.shared),
                                         self.specs.sources[0].topic)]
        self.pub_truth = self.create_publisher(Float64MultiArray, "sim/truth", qos.TRUTH)
        if cfg["publish_clock"]:
            if not cfg["time_scale"] > 0 or not cfg["clock_start"] > 0:
                raise ConfigError("time_scale and clock_start must be > 0")
            period = 1.0 / (cfg["rate"] * cfg["time_scale"])
            self.timer = self.create_timer(period, self.tick_callback, clock=Clock(clock_type=ClockType.STEADY_TIME))
        else:
            self.timer = self.create_timer(1.0 / cfg["rate"], self.tick_callback)
        self.get_logger().info(
            f"camera_sim: system '{sys_.name}', {cfg['rate']:g} Hz, schedule {mode}, "
            f"{'clock ' + format(cfg['time_scale'], 'g') + 'x' if cfg['publish_clock'] else 'node clock'}")

    def _ready(self) -> bool:
        c = self.cfg
        if self.pub_target.get_subscription_count() < c["wait_for_subscribers"]:
            return False
        if self.pub_truth.get_subscription_count() < c["wait_for_truth_subscribers"]:
            return False
        return True

    def tick_callback(self) -> None:
        c = self.cfg
        if not self.started:
            if not self._ready():
                return
            self.started = True
            self.k = -1
            if c["publish_clock"]:
                self.epoch_ns = round(c["clock_start"] * 1e9)
            else:
                self.epoch_ns = self._timer_grid(self.get_clock().now().nanoseconds)
            self.get_logger().info("subscribers present: starting the simulation")
        if c["publish_clock"]:
            k = self.k + 1
        else:
            # the tick due now on the node clock (ticks that a slow timer missed are skipped)
            k = (self.get_clock().now().nanoseconds - self.epoch_ns) // self.period_ns
            if k <= self.k:
                return
        if self.k_end is not None and k > self.k_end:
            self.get_logger().info(f"duration {c['duration']} s reached: exiting")
            self.timer.cancel()
            raise SystemExit(0)
        self.k = k
        self.publish_tick(k)

    def _timer_grid(self, now_ns: int) -> int:
        """The time this timer call was due (``now`` less its lateness): the epoch on the timer's
        own grid, so that each later call, due one period after the last and late by less than a
        period, finds exactly the next tick due. An epoch at ``now`` would put the grid of stamps
        at the first call's random lateness: every later call that runs less late than the first
        would find no new tick due, and the call after it would skip one (a tick dropped with no
        load at all). ``now`` itself when the timer cannot say."""
        left = self.timer.time_until_next_call()
        if left is None or not 0 <= left <= self.period_ns:
            return now_ns
        return now_ns + left - self.period_ns

    def publish_tick(self, k: int) -> None:
        stamp_ns = self.epoch_ns + k * self.period_ns
        if self.cfg["stamp_at_send"] and not self.cfg["publish_clock"]:   # the clock now, never back
            stamp_ns = max(self.get_clock().now().nanoseconds, self.last_stamp_ns + 1)
        self.last_stamp_ns = stamp_ns
        t = (stamp_ns - self.epoch_ns) * 1e-9
        stamp = mb.ns_to_stamp(stamp_ns)
        if self.pub_clock is not None:
            self.pub_clock.publish(ClockMsg(clock=stamp))
        self.plant.advance(t, w=None if self.accel is None else self.accel(self.plant.t))   # held over the step
        rho = int(self.schedule.channel_at(t))
        y = self.plant.measure(rho, noise_std=0.0)
        if self.cfg["noise_std"] > 0:
            y = y + self.cfg["noise_std"] * self.rng.standard_normal(y.shape)
        if self.bias is not None:
            y = self.bias.add(t, rho, y)
        switching = rho != self.switch[0]
        if switching:
            self.switch = (rho, stamp_ns)
        # while the camera turns (dead time) only the shared sources (its own pose) publish; the channel
        # message first on a switching tick, after the poses on the others (module docstring)
        msgs = self.outputs.messages(rho, y, stamp_ns, self.frame, self.schedule.blind_at(t),
                                     self.switch[1] if self.stamped else None, self.offset_ns, switching=switching)
        if self.cfg["channel_last"] and self.specs.channel_topic and msgs[0][0] == self.specs.channel_topic:
            msgs = msgs[1:] + msgs[:1]
        for topic, msg in msgs:
            self.pubs[topic].publish(msg)
        self.pub_truth.publish(mb.labelled_array(self.plant.x, self.labels, stamp_ns))


def main(args=None) -> int:
    try:
        return run_node(CameraSimNode, "camera_sim", args)
    except SystemExit as done:   # duration reached
        return int(done.code or 0)


if __name__ == "__main__":
    sys.exit(main())
