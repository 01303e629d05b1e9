"""The estimator node: the switched Luenberger observer of switchobs_core on ROS 2 topics.

``ros2 run switchobs_ros estimator --ros-args --params-file config/estimator.yaml``

Thin glue (shared/DESIGN.md): parameters, topics, QoS, clocks, diagnostics. The estimation
is :class:`switchobs_core.observer.SwitchedObserver`; messages go through :mod:`msg_bridge`.

Measurement pairing
-------------------
Channel rho's output is ``y = [p_camera; p_target]``. ``camera/pose`` and ``target/pose``
arrive separately with (normally) the same header stamp: the node keeps the pending samples
by stamp (up to 8) and calls ``observer.update(t, rho, y)`` when both halves are there. A half
whose partner does not come (a newer pair completes, or ``pairing_timeout`` passes) is used alone
through the observer's partial-rows input (``rows=``). The target pose is attributed to the
latest channel received on ``camera/active_channel`` (UInt8 has no stamp): a publisher must
send the new channel before the first target pose of that channel (camera_sim does).

Time: observer time is ``(stamp - origin)`` in seconds, with ``origin`` the stamp of the first
sample accepted after start-up or a reset (integer nanoseconds until that subtraction).
Every output carries the stamp of the sample it answers.

Clock jumps: a jump of the node clock backwards (with ``use_sim_time``, a looped bag restarting
its ``/clock``) resets the estimator, so the replay's samples are accepted again and the
estimate converges again; a jump forwards by more than ``sensor_timeout`` is counted. Both are
reported in ``/diagnostics``. Replays must therefore publish ``/clock`` (the bag tools do): stamps
that go back without the clock going back are rejected as ``old_stamp``, never silently used.
"""

from __future__ import annotations

import math
import sys
import time
from collections import Counter

import numpy as np
import rclpy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import PoseStamped
from nav_msgs.msg import Odometry
from rclpy.clock import JumpThreshold, TimeJump
from rclpy.duration import Duration
from rclpy.exceptions import ParameterException
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from std_msgs.msg import Float64MultiArray, UInt8
from std_srvs.srv import Trigger

import msg_bridge as mb
from msg_bridge import Reason, Rejection
from switchobs_core.exceptions import SwitchobsError
from switchobs_core.threads import single_threaded_blas

from . import qos
from .core_config import (
    camera_target_rows,
    cycles_from_params,
    load_or_design_table,
    load_system_param,
)
from .params import ConfigError, Param, declare_all

__all__ = ["PARAMS", "EstimatorNode", "main"]

PARAMS = [
    Param("system", "paper", "The system: a built-in scenario name (paper, camera_agents) or a path to a "
          "system YAML file."),
    Param("gain_table", "", "Path of the gain table (JSON, from `switchobs design`). Empty: use a cached "
          "table for this system/schedule/delta, or design one at start-up and write it to gain_table_cache_dir."),
    Param("gain_table_cache_dir", "~/.cache/switchobs", "Folder for gain tables designed at start-up."),
    Param("delta", 0.99, "Contraction target delta of the design (used only when designing at start-up)."),
    Param("schedule.mode", "periodic", "periodic (one cycle), sequence (cycles repeated in order) or robust "
          "(the table's residence-time-box design; needs schedule.h_min/h_max to design)."),
    Param("schedule.tau", (2.0,), "Cycle lengths tau_k in seconds (two-channel systems).", float),
    Param("schedule.s", (0.6,), "Duty fractions s_k = h_1/tau_k, one per schedule.tau entry.", float),
    Param("schedule.h", (), "N-channel cycles: N active times per cycle, cycles concatenated "
          "(overrides schedule.tau/s when set).", float),
    Param("schedule.h_min", 0.0, "Robust mode: shortest residence time h_min of assumption A2 (s)."),
    Param("schedule.h_max", 0.0, "Robust mode: longest residence time h_max of assumption A2 (s)."),
    Param("initial_estimate", (), "Initial estimate x_hat(t0), n values in state order (empty: zeros).", float),
    Param("e0", 1.0, "Bound on the initial error ||x_hat(t0) - x(t0)|| used by the envelopes and the exact bound."),
    Param("world_frame", "map", "frame_id of the published odometry (and of the expected input poses)."),
    Param("input_frame_id", "map", "Expected header.frame_id of camera/pose and target/pose ('' accepts any)."),
    Param("body_frames", (), "child_frame_id of each body's odometry, in body order (empty: the body names "
          "camera, agent1, ...).", str),
    Param("camera_body", "camera", "Name of the camera body in the system's state and output labels."),
    Param("sensor_timeout", 0.5, "Seconds without an accepted measurement after which diagnostics turn WARN."),
    Param("future_tolerance", 0.5, "Seconds a stamp may lie ahead of the node clock before it is rejected."),
    Param("max_abs_value", 1.0e6, "Largest accepted |coordinate| of an input pose (m)."),
    Param("pairing_timeout", 0.2, "Seconds (wall) to wait for the other half of a camera/target pair before "
          "using one half alone."),
    Param("diagnostics_period", 1.0, "Period of /diagnostics in seconds (node clock)."),
]

_PARTS = ("camera", "target")
#: Samples kept waiting for their other half (a backlog reorders the two topics a little).
MAX_PENDING = 8


class _Pending:
    """One sample being assembled: the halves that have arrived for one stamp."""

    __slots__ = ("channel", "since", "stamp_ns", "xy")

    def __init__(self, stamp_ns: int):
        self.stamp_ns = stamp_ns
        self.xy: dict[str, np.ndarray] = {}
        self.channel = 0
        self.since = time.monotonic()


class EstimatorNode(Node):
    """Subscribes the camera topics, drives a SwitchedObserver, publishes the estimate."""

    def __init__(self, **kwargs):
        super().__init__("estimator", **kwargs)
        self.t_start = time.monotonic()
        cfg = declare_all(self, PARAMS)
        self.cfg = cfg
        self._configure(cfg)
        self.get_logger().info(
            f"estimator ready: system '{self.system.name}' (n={self.system.n}, N={self.system.N}), "
            f"mode {self.mode}, cycles {[c.label() for c in self.cycles]}, table {self.table_path}, "
            f"start-up {time.monotonic() - self.t_start:.2f} s")

    # ------------------------------------------------------------------ configuration
    def _configure(self, cfg: dict) -> None:
        from switchobs_core.observer import MODES, SwitchedObserver

        self.system = sys_ = load_system_param(cfg["system"])
        self.mode = cfg["schedule.mode"]
        if self.mode not in MODES:
            raise ConfigError(f"parameter 'schedule.mode' must be one of {', '.join(MODES)}; got '{self.mode}'")
        robust = None
        if self.mode == "robust":
            hmin, hmax = cfg["schedule.h_min"], cfg["schedule.h_max"]
            if not 0 < hmin <= hmax:
                raise ConfigError(f"robust mode needs 0 < schedule.h_min <= schedule.h_max; got {hmin}, {hmax}")
            robust = (hmin, hmax)
            self.cycles = []
        else:
            self.cycles = cycles_from_params(self.mode, cfg["schedule.tau"], cfg["schedule.s"],
                                             cfg["schedule.h"], sys_.N)
        for name in ("delta", "e0", "sensor_timeout", "future_tolerance", "max_abs_value",
                     "pairing_timeout", "diagnostics_period"):
            v = cfg[name]
            if not (math.isfinite(v) and v > 0) and not (name == "e0" and v == 0):
                raise ConfigError(f"parameter '{name}' must be a finite number > 0; got {v}")
        x0 = cfg["initial_estimate"]
        if x0 and len(x0) != sys_.n:
            raise ConfigError(f"parameter 'initial_estimate' has {len(x0)} values; the system has n = {sys_.n} "
                              f"states ({', '.join(sys_.state_labels)})")
        self.x0 = np.array(x0, dtype=float) if x0 else np.zeros(sys_.n)
        self.rows = camera_target_rows(sys_, cfg["camera_body"])
        self.bodies = mb.bodies(sys_.state_labels)
        frames = cfg["body_frames"]
        if frames and len(frames) != len(self.bodies):
            raise ConfigError(f"parameter 'body_frames' has {len(frames)} names for {len(self.bodies)} bodies "
                              f"({', '.join(b.name for b in self.bodies)})")
        self.child_frames = list(frames) if frames else [b.name for b in self.bodies]
        self.table, self.table_path = load_or_design_table(
            cfg["gain_table"], cfg["gain_table_cache_dir"], sys_, self.mode, self.cycles, robust,
            cfg["delta"], self.get_logger().info)
        try:
            self.observer = SwitchedObserver(sys_, self.table, mode=self.mode, cycles=self.cycles or None,
                                             x0=self.x0, t0=0.0, e0=cfg["e0"], bounds=robust)
        except SwitchobsError as err:
            raise ConfigError(f"observer: {err}") from None
        self.state_labels = tuple(sys_.state_labels)
        self.env_labels = mb.envelope_labels(sys_.N)
        self.frame = cfg["world_frame"]
        self.w_state = mb.LabelledArrayWriter(self.state_labels)
        self.w_env = mb.LabelledArrayWriter(self.env_labels)
        self.w_odom = [mb.OdometryWriter(b, self.frame, c) for b, c in zip(self.bodies, self.child_frames)]
        self.in_frame = cfg["input_frame_id"]
        self.max_abs = cfg["max_abs_value"]
        self.future_ns = int(cfg["future_tolerance"] * 1e9)
        self.pair_timeout = cfg["pairing_timeout"]
        self.sensor_timeout = cfg["sensor_timeout"]

        # run-time state (cleared by reset)
        self.channel = 0
        self.last_ns: dict[str, int | None] = {p: None for p in _PARTS}
        self.pending: dict[int, _Pending] = {}   # by stamp (ns)
        self.origin_ns: int | None = None
        self.obs_ns: int | None = None     # stamp of the last observer update
        self.last_accept_clock_ns: int | None = None
        # counters (never cleared: diagnostics report totals)
        self.accepted = Counter()          # per input topic
        self.rejected = Counter()          # per (topic, reason)
        self.updates = 0
        self.partial_updates = 0
        self.switches = 0
        self.resets = 0
        self.errors = 0
        self.last_rejection = ""
        self._rate_base = (self.get_clock().now().nanoseconds, Counter(), 0)

        # publishers (reliable), then subscriptions (sensor data; channel reliable). The
        # channel subscription is created first so that, when a channel message and a pose
        # are ready together, the executor takes the channel first.
        self.pub_state = self.create_publisher(Float64MultiArray, "~/state", qos.OUTPUT)
        self.pub_env = self.create_publisher(Float64MultiArray, "~/envelope", qos.OUTPUT)
        self.pub_odom = [self.create_publisher(Odometry, f"~/{b.name}/odom", qos.OUTPUT) for b in self.bodies]
        self.pub_diag = self.create_publisher(DiagnosticArray, "/diagnostics", qos.OUTPUT)
        self.sub_channel = self.create_subscription(UInt8, "camera/active_channel", self.channel_callback,
                                                    qos.CHANNEL_SUB)
        self.sub_camera = self.create_subscription(PoseStamped, "camera/pose", self.camera_callback, qos.SENSOR_SUB)
        self.sub_target = self.create_subscription(PoseStamped, "target/pose", self.target_callback, qos.SENSOR_SUB)
        self.srv_reset = self.create_service(Trigger, "~/reset", self.reset_callback)
        self.clock_jumps_back = 0
        self.clock_jumps_forward = 0
        self.last_clock_jump = ""
        self._jump_handle = self.get_clock().create_jump_callback(
            JumpThreshold(min_forward=Duration(nanoseconds=int(self.sensor_timeout * 1e9)),
                          min_backward=Duration(nanoseconds=-1), on_clock_change=False),
            post_callback=self.clock_jump_callback)
        self.diag_timer = self.create_timer(cfg["diagnostics_period"], self.diagnostics_callback)
        self.pair_timer = self.create_timer(max(self.pair_timeout / 2, 0.005), self.pairing_callback)

    # ------------------------------------------------------------------ inputs
    def channel_callback(self, msg: UInt8) -> None:
        try:
            rej = mb.check_channel(msg, self.system.N)
            if rej is not None:
                self._reject("camera/active_channel", rej)
                return
            self.accepted["camera/active_channel"] += 1
            c = int(msg.data)
            if c != self.channel:
                if self.channel:
                    self.switches += 1
                self.channel = c
        except Exception as err:
            self._internal_error("camera/active_channel", err)

    def camera_callback(self, msg: PoseStamped) -> None:
        self._pose("camera", "camera/pose", msg)

    def target_callback(self, msg: PoseStamped) -> None:
        self._pose("target", "target/pose", msg)

    def _pose(self, part: str, topic: str, msg: PoseStamped) -> None:
        try:
            now_ns = self.get_clock().now().nanoseconds
            rej = mb.check_pose(msg, frame_id=self.in_frame, max_abs=self.max_abs, last_ns=self.last_ns[part],
                                now_ns=now_ns, future_tolerance_ns=self.future_ns)
            stamp_ns = mb.stamp_to_ns(msg.header.stamp)
            if rej is None and not self.channel:
                rej = Rejection(Reason.NO_CHANNEL, "camera/active_channel", "no active channel received yet")
            if rej is None and self.obs_ns is not None and stamp_ns <= self.obs_ns:
                rej = Rejection(Reason.OLD_STAMP, "header.stamp",
                                f"not newer than the estimate ({(self.obs_ns - stamp_ns) * 1e-9:.6f} s older)")
            if rej is not None:
                self._reject(topic, rej)
                return
            self.accepted[topic] += 1
            self.last_ns[part] = stamp_ns
            self.last_accept_clock_ns = now_ns
            pend = self.pending.get(stamp_ns)
            if pend is None:
                pend = self.pending[stamp_ns] = _Pending(stamp_ns)
                if len(self.pending) > MAX_PENDING:      # the oldest half's partner is overdue
                    self._flush(min(self.pending))
            pend.xy[part] = mb.pose_to_xy(msg)
            if part == "target" or not pend.channel:
                pend.channel = self.channel
            if len(pend.xy) == 2:
                # older samples will not be completed now: use their halves alone, in order
                for s_old in sorted(s for s in self.pending if s < stamp_ns):
                    self._flush(s_old)
                self._flush(stamp_ns)
        except Exception as err:
            self._internal_error(topic, err)

    def pairing_callback(self) -> None:
        try:
            now = time.monotonic()
            for s in sorted(self.pending):
                if now - self.pending[s].since <= self.pair_timeout:
                    break
                self._flush(s)
        except Exception as err:
            self._internal_error("pairing", err)

    def _flush(self, stamp_ns: int) -> None:
        """Run the observer on a pending sample (both halves, or one alone) and publish."""
        pend = self.pending.pop(stamp_ns, None)
        if pend is None or (self.obs_ns is not None and stamp_ns <= self.obs_ns):
            return
        c = pend.channel
        (cx, cy), (tx, ty) = self.rows[c - 1]
        cam, tgt = pend.xy.get("camera"), pend.xy.get("target")
        if cam is not None and tgt is not None:
            y = np.empty(4)
            y[cx], y[cy], y[tx], y[ty] = cam[0], cam[1], tgt[0], tgt[1]
            rows = None
        elif cam is not None:
            y, rows = cam, (cx, cy)
        else:
            y, rows = tgt, (tx, ty)
        if self.origin_ns is None:
            self.origin_ns = pend.stamp_ns
            self.observer.reset(self.x0, 0.0)
        t = (pend.stamp_ns - self.origin_ns) * 1e-9
        x_hat = self.observer.update(t, c, y, rows=rows)
        self.obs_ns = pend.stamp_ns
        self.updates += 1
        if rows is not None:
            self.partial_updates += 1
        self._publish(pend.stamp_ns, x_hat)

    def _publish(self, stamp_ns: int, x_hat: np.ndarray) -> None:
        env = self.observer.envelope()
        env_vals = np.concatenate([env.z, [env.paper_bound, env.exact_bound]])
        if not (np.isfinite(x_hat).all() and np.isfinite(env_vals).all()):
            self.errors += 1
            self.get_logger().error("non-finite estimate: not published; resetting the estimator")
            self.reset_estimator("non-finite estimate")
            return
        self.pub_state.publish(self.w_state.msg(x_hat, stamp_ns))
        self.pub_env.publish(self.w_env.msg(env_vals, stamp_ns))
        for pub, w in zip(self.pub_odom, self.w_odom):
            pub.publish(w.msg(x_hat, stamp_ns))

    def _reject(self, topic: str, rej: Rejection) -> None:
        self.rejected[(topic, rej.reason.value)] += 1
        self.last_rejection = f"{topic}: {rej}"
        self.get_logger().warn(f"rejected {topic}: {rej}", throttle_duration_sec=1.0)

    def _internal_error(self, where: str, err: Exception) -> None:
        self.errors += 1
        self.rejected[(where, "internal_error")] += 1
        self.last_rejection = f"{where}: internal_error: {type(err).__name__}: {err}"
        self.get_logger().error(f"{where}: {type(err).__name__}: {err}", throttle_duration_sec=1.0)

    # ------------------------------------------------------------------ reset
    def reset_estimator(self, why: str) -> None:
        """Back to the initial estimate; the next accepted sample becomes the new time origin.

        Clears the pending sample and the per-topic stamp history (so a replay that starts
        over is accepted); keeps the active channel and all counters.
        """
        self.pending = {}
        self.origin_ns = None
        self.obs_ns = None
        self.last_ns = {p: None for p in _PARTS}
        self.observer.reset(self.x0, 0.0)
        self.resets += 1
        self.get_logger().info(f"estimator reset ({why})")

    def clock_jump_callback(self, jump: TimeJump) -> None:
        """A jump of the node clock: backwards resets the estimator (a looped replay), forwards is counted."""
        try:
            delta = jump.delta.nanoseconds * 1e-9
            if delta < 0:
                self.clock_jumps_back += 1
                self.last_clock_jump = f"back by {-delta:.6g} s"
                self.reset_estimator(f"clock jumped back by {-delta:.6g} s")
            else:
                self.clock_jumps_forward += 1
                self.last_clock_jump = f"forward by {delta:.6g} s"
                self.get_logger().warn(f"clock jumped forward by {delta:.6g} s")
        except Exception as err:
            self._internal_error("clock jump", err)

    def reset_callback(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        self.reset_estimator("~/reset service")
        response.success = True
        response.message = f"reset to the initial estimate (reset #{self.resets})"
        return response

    # ------------------------------------------------------------------ diagnostics
    def diagnostics_callback(self) -> None:
        try:
            self.pub_diag.publish(self.diagnostics())
        except Exception as err:
            self._internal_error("diagnostics", err)

    def diagnostics(self) -> DiagnosticArray:
        """The /diagnostics message: configuration, observer, inputs."""
        now = self.get_clock().now()
        now_ns = now.nanoseconds

        def kv(k, v):
            return KeyValue(key=str(k), value=v if isinstance(v, str) else _fmt(v))

        obs = self.observer
        # configuration (static)
        conf = [kv("system", self.system.name), kv("fingerprint", self.system.fingerprint()[:16]),
                kv("gain_table", str(self.table_path)), kv("mode", self.mode),
                kv("cycles", " ".join(c.label() for c in self.cycles) or "robust"),
                kv("e0", obs.e0)]
        for k, d in enumerate(obs.designs):
            conf.append(kv(f"design[{k}].eta", d.eta))
            conf.append(kv(f"design[{k}].kappa", d.kappa))
            conf.append(kv(f"design[{k}].f (paper factors)", d.f))
        # observer (dynamic)
        d = obs.current_design
        cyc = getattr(d, "cycle", None)
        ob = [kv("channel", obs.channel), kv("estimate time (s since origin)", obs.t),
              kv("current cycle tau", cyc.tau if cyc is not None else "robust"),
              kv("current cycle s", cyc.s if cyc is not None else "robust"),
              kv("current design index", obs.design_index), kv("current eta", d.eta), kv("current kappa", d.kappa),
              kv("current gain norms |L_i|", [float(np.linalg.norm(L, 2)) for L in d.L]),
              kv("updates", self.updates), kv("partial updates", self.partial_updates),
              kv("switches", self.switches), kv("resets", self.resets),
              kv("clock jumps back (resets)", self.clock_jumps_back),
              kv("clock jumps forward", self.clock_jumps_forward)]
        if self.last_clock_jump:
            ob.append(kv("last clock jump", self.last_clock_jump))
        recs = obs.completed_cycles
        if recs:
            r = recs[-1]
            ob += [kv("cycles completed", len(recs)), kv("last cycle measured tau", r.tau),
                   kv("last cycle measured s", r.s), kv("last cycle measured h", r.h),
                   kv("last cycle paper factors f", r.f), kv("last cycle matched schedule", r.matched)]
        else:
            ob.append(kv("cycles completed", 0))
        if self.origin_ns is not None:
            env = obs.envelope()
            ob += [kv("paper bound", env.paper_bound), kv("exact bound", env.exact_bound)]
        level, msg = DiagnosticStatus.OK, "estimating"
        if self.last_accept_clock_ns is None:
            level, msg = DiagnosticStatus.WARN, "waiting for measurements"
        else:
            age = (now_ns - self.last_accept_clock_ns) * 1e-9
            ob.append(kv("seconds since last measurement", age))
            if age > self.sensor_timeout:
                level = DiagnosticStatus.WARN
                msg = f"no measurement for {age:.2f} s (sensor_timeout {self.sensor_timeout} s)"
        if recs and not recs[-1].matched:
            level = max(level, DiagnosticStatus.WARN)
            msg += "; last cycle did not match the schedule"
        # inputs: rates over the last period (node clock), rejected totals by reason
        t0_ns, acc0, _ = self._rate_base
        dt = (now_ns - t0_ns) * 1e-9
        inp = []
        for topic in ("camera/pose", "target/pose", "camera/active_channel"):
            rate = (self.accepted[topic] - acc0[topic]) / dt if dt > 0 else 0.0
            inp.append(kv(f"{topic} rate (Hz)", rate))
            inp.append(kv(f"{topic} accepted", self.accepted[topic]))
        total_rej = sum(self.rejected.values())
        for (topic, reason), n in sorted(self.rejected.items()):
            inp.append(kv(f"rejected {topic} {reason}", n))
        inp.append(kv("rejected total", total_rej))
        if self.last_rejection:
            inp.append(kv("last rejection", self.last_rejection))
        new_rej = total_rej - self._rate_base[2]
        self._rate_base = (now_ns, Counter(self.accepted), total_rej)
        arr = DiagnosticArray()
        arr.header.stamp = now.to_msg()
        name = self.get_fully_qualified_name()
        arr.status = [
            DiagnosticStatus(level=DiagnosticStatus.OK, name=f"{name}: configuration", message="loaded",
                             hardware_id="switchobs", values=conf),
            DiagnosticStatus(level=level, name=f"{name}: observer", message=msg, hardware_id="switchobs",
                             values=ob),
            DiagnosticStatus(level=DiagnosticStatus.WARN if new_rej else DiagnosticStatus.OK,
                             name=f"{name}: inputs",
                             message=f"{new_rej} rejected in the last period" if new_rej else "ok",
                             hardware_id="switchobs", values=inp),
        ]
        return arr


def _fmt(v) -> str:
    if isinstance(v, bool):
        return str(v).lower()
    if isinstance(v, float):
        return f"{v:.6g}"
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_fmt(x) for x in v) + "]"
    return str(v)


def run_node(node_cls, prog: str, args=None) -> int:
    """Jazzy main pattern, plus: a bad configuration exits 2 with one line on stderr."""
    single_threaded_blas()  # small matrices; see switchobs_core.threads
    try:
        rclpy.init(args=args)
    except Exception as err:
        print(f"{prog}: error: cannot start ROS 2: {_one_line(err)}", file=sys.stderr)
        return 2
    node = None
    try:
        node = node_cls()
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except (ConfigError, ParameterException) as err:
        print(f"{prog}: error: {_one_line(err)}", file=sys.stderr)
        return 2
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    return getattr(node, "exit_code", 0)


def _one_line(err: Exception) -> str:
    text = " ".join(str(err).split())
    return text or type(err).__name__


def main(args=None) -> int:
    return run_node(EstimatorNode, "estimator", args)


if __name__ == "__main__":
    sys.exit(main())
