"""The estimator node: the switched Luenberger observer of switchobs_core on ROS 2 topics.

``ros2 run switchobs_ros estimator --ros-args --params-file config/estimator.yaml``

Thin glue (shared/DESIGN.md): parameters, topics, QoS, clocks, diagnostics. The estimation
is :class:`switchobs_core.observer.SwitchedObserver`; messages go through :mod:`msg_bridge`.

Input handling (validation, measurement pairing, the observer, the counters) is
:class:`switchobs_ros.pipeline.EstimatorPipeline`, shared with the offline bag tools
(``switchobs_bag estimate``); this module is the rclpy glue around it: parameters,
subscriptions, publishing each estimate, the pairing timer (``pairing_timeout``, wall clock),
the clock-jump callback, ``~/reset`` and ``/diagnostics``.

Measurement pairing (see the pipeline): channel rho's output is ``y = [p_camera; p_target]``;
``camera/pose`` and ``target/pose`` are paired by header stamp, a half whose partner does not
come is used alone. The target pose is attributed to the latest channel received on
``camera/active_channel`` (UInt8 has no stamp): a publisher must send the new channel before
the first target pose of that channel (camera_sim does).

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
from switchobs_core.threads import single_threaded_blas

from . import qos
from .params import ConfigError, Param, declare_all
from .pipeline import Estimate, EstimatorPipeline, PipelineLog

__all__ = ["PARAMS", "PREDICTION_BOUND_LABELS", "EstimatorNode", "main"]

#: Element names of ``~/prediction/bound``.
PREDICTION_BOUND_LABELS = ("exact_bound", "seconds_since_measurement")

PARAMS = [
    Param("system", "paper", "The system: a built-in scenario name (paper, camera_agents) or a path to a "
          "system YAML file."),
    Param("gain_table", "", "Path of the gain table (JSON, from `switchobs design`). Empty: use a cached "
          "table for this system/schedule/delta, or design one at start-up and write it to gain_table_cache_dir."),
    Param("gain_table_cache_dir", "~/.cache/switchobs", "Folder for gain tables designed at start-up."),
    Param("delta", 0.99, "Contraction target delta of the design (used only when designing at start-up)."),
    Param("gain_family", "", "Gain family: '' (the table's: lmi or kalman), 'kalman-online' (the Riccati recursion "
          "online, any schedule), or, when designing at start-up, 'lmi' (the paper's gains) or 'kalman' (offline "
          "periodic Kalman gains; needs rate)."),
    Param("rate", 0.0, "Nominal sample rate in Hz: needed to design a kalman table at start-up (0: not set)."),
    Param("noise.measurement_std", -1.0, "Measurement noise std on every output row (m) for the covariance and the "
          "Kalman families (< 0: the system's noise: section, or 1 mm)."),
    Param("noise.process_std", -1.0, "Process noise q on every state, intensity q^2 I (< 0: the system's noise: "
          "section, or 0.01)."),
    Param("publish_covariance", True, "Publish ~/covariance and fill the odometry covariances from the error "
          "covariance P (for the LMI family P is propagated under the noise model: about n^3 flops per sample)."),
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
    Param("max_abs_value", 1.0e6, "Largest accepted |coordinate| of an input pose (m). At most 1e150 (the observer "
          "refuses larger samples: the next exact step could overflow)."),
    Param("pairing_timeout", 0.2, "Seconds (wall) to wait for the other half of a camera/target pair before "
          "using one half alone."),
    Param("diagnostics_period", 1.0, "Period of /diagnostics in seconds (node clock)."),
]

class _NodeLog(PipelineLog):
    """The pipeline's log on the node's logger (repeating messages throttled to one per second
    and level).

    The throttle is ours, not rclpy's ``throttle_duration_sec``: rclpy looks up the caller's
    frame with ``inspect`` on every call, even one it then suppresses, which cost about 0.7 ms
    per rejected message (measured), so a flood of bad input would eat the CPU that valid
    measurements need. Suppressed messages are still counted in /diagnostics.
    """

    THROTTLE_S = 1.0

    def __init__(self, logger):
        self._logger = logger
        self._next = {"warn": 0.0, "error": 0.0}

    def _due(self, level: str) -> bool:
        now = time.monotonic()
        if now < self._next[level]:
            return False
        self._next[level] = now + self.THROTTLE_S
        return True

    def info(self, text: str) -> None:
        self._logger.info(text)

    def warn(self, text: str, throttle: bool = False) -> None:
        if not throttle or self._due("warn"):
            self._logger.warn(text)

    def error(self, text: str, throttle: bool = False) -> None:
        if not throttle or self._due("error"):
            self._logger.error(text)


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
        # the input handling (validation, pairing, observer, counters) is the pipeline's
        self.pipeline = pl = EstimatorPipeline.from_params(cfg, _NodeLog(self.get_logger()))
        self.system = sys_ = pl.system
        self.mode = pl.mode
        self.cycles = pl.cycles
        self.table, self.table_path = pl.table, pl.table_path
        self.observer = pl.observer
        self.bodies = mb.bodies(sys_.state_labels)
        frames = cfg["body_frames"]
        if frames and len(frames) != len(self.bodies):
            raise ConfigError(f"parameter 'body_frames' has {len(frames)} names for {len(self.bodies)} bodies "
                              f"({', '.join(b.name for b in self.bodies)})")
        self.child_frames = list(frames) if frames else [b.name for b in self.bodies]
        self.state_labels = tuple(sys_.state_labels)
        self.env_labels = mb.envelope_labels(sys_.N)
        self.frame = cfg["world_frame"]
        self.w_state = mb.LabelledArrayWriter(self.state_labels)
        self.w_env = mb.LabelledArrayWriter(self.env_labels)
        self.w_odom = [mb.OdometryWriter(b, self.frame, c) for b, c in zip(self.bodies, self.child_frames)]
        self.pair_timeout = cfg["pairing_timeout"]
        self.sensor_timeout = cfg["sensor_timeout"]
        self._rate_base = (self.get_clock().now().nanoseconds, Counter(), 0)

        # publishers (reliable), then subscriptions (sensor data; channel reliable). The
        # channel subscription is created first so that, when a channel message and a pose
        # are ready together, the executor takes the channel first.
        self.pub_state = self.create_publisher(Float64MultiArray, "~/state", qos.OUTPUT)
        self.pub_env = self.create_publisher(Float64MultiArray, "~/envelope", qos.OUTPUT)
        self.pub_cov = None
        if pl.publish_covariance:
            self.w_cov = mb.LabelledArrayWriter(mb.covariance_labels(self.state_labels))
            self.pub_cov = self.create_publisher(Float64MultiArray, "~/covariance", qos.OUTPUT)
        self.pub_odom = [self.create_publisher(Odometry, f"~/{b.name}/odom", qos.OUTPUT) for b in self.bodies]
        self.pub_diag = self.create_publisher(DiagnosticArray, "/diagnostics", qos.OUTPUT)
        # sensor outage: the prediction and its exact bound, once per diagnostics period, on
        # topics of their own (~/state stays one answer per measurement)
        self.pub_pred = self.create_publisher(Float64MultiArray, "~/prediction", qos.OUTPUT)
        self.pub_pred_bound = self.create_publisher(Float64MultiArray, "~/prediction/bound", qos.OUTPUT)
        self.w_pred_bound = mb.LabelledArrayWriter(PREDICTION_BOUND_LABELS)
        self.predictions = 0
        self.last_prediction = None
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
        self.pipeline.on_channel(msg)

    def camera_callback(self, msg: PoseStamped) -> None:
        self._publish_all(self.pipeline.on_pose("camera", msg, self.get_clock().now().nanoseconds))

    def target_callback(self, msg: PoseStamped) -> None:
        self._publish_all(self.pipeline.on_pose("target", msg, self.get_clock().now().nanoseconds))

    def pairing_callback(self) -> None:
        self._publish_all(self.pipeline.flush_overdue(time.monotonic(), self.pair_timeout))

    def _publish_all(self, estimates: list[Estimate]) -> None:
        try:
            for e in estimates:
                self.pub_state.publish(self.w_state.msg(e.x_hat, e.stamp_ns))
                self.pub_env.publish(self.w_env.msg(e.envelope, e.stamp_ns))
                if self.pub_cov is not None and e.P is not None:
                    self.pub_cov.publish(self.w_cov.msg(e.P.ravel(), e.stamp_ns))
                for pub, w in zip(self.pub_odom, self.w_odom):
                    pub.publish(w.msg(e.x_hat, e.stamp_ns, e.P))
        except Exception as err:
            self.pipeline.internal_error("publish", err)

    # ------------------------------------------------------------------ reset
    def reset_estimator(self, why: str) -> None:
        """Back to the initial estimate (see :meth:`EstimatorPipeline.reset`)."""
        self.pipeline.reset(why)

    def clock_jump_callback(self, jump: TimeJump) -> None:
        """A jump of the node clock: backwards resets the estimator (a looped replay), forwards is counted."""
        try:
            delta = jump.delta.nanoseconds * 1e-9
            if delta < 0:
                self.clock_jumps_back += 1
                self.last_clock_jump = f"back by {-delta:.6g} s"
                self.reset_estimator(f"clock jumped back by {-delta:.6g} s")
            elif self.get_clock().now().nanoseconds == jump.delta.nanoseconds:
                pass     # the first /clock of a sim-time clock (from 0): the clock starts, no jump
            else:
                self.clock_jumps_forward += 1
                self.last_clock_jump = f"forward by {delta:.6g} s"
                self.get_logger().warn(f"clock jumped forward by {delta:.6g} s")
        except Exception as err:
            self.pipeline.internal_error("clock jump", err)

    def reset_callback(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        self.reset_estimator("~/reset service")
        response.success = True
        response.message = f"reset to the initial estimate (reset #{self.pipeline.resets})"
        return response

    # ------------------------------------------------------------------ diagnostics
    def diagnostics_callback(self) -> None:
        try:
            self.prediction_tick(self.get_clock().now().nanoseconds)
        except Exception as err:
            self.pipeline.internal_error("prediction", err)
        try:
            self.pub_diag.publish(self.diagnostics())
        except Exception as err:
            self.pipeline.internal_error("diagnostics", err)

    def prediction_tick(self, now_ns: int) -> None:
        """During a sensor outage (no accepted measurement for sensor_timeout), publish the
        observer's prediction at the node clock on ``~/prediction`` and its exact bound on
        ``~/prediction/bound`` (stamped with the node clock, not a measurement stamp)."""
        last = self.pipeline.last_accept_clock_ns
        if last is None or (now_ns - last) * 1e-9 <= self.sensor_timeout:
            return
        p = self.pipeline.predict(now_ns)
        if p is None:
            return
        self.pub_pred.publish(self.w_state.msg(p.x_hat, p.stamp_ns))
        self.pub_pred_bound.publish(self.w_pred_bound.msg(np.array([p.exact_bound, p.age]), p.stamp_ns))
        self.predictions += 1
        self.last_prediction = p

    def diagnostics(self) -> DiagnosticArray:
        """The /diagnostics message: configuration, observer, inputs."""
        now = self.get_clock().now()
        now_ns = now.nanoseconds

        def kv(k, v):
            return KeyValue(key=str(k), value=v if isinstance(v, str) else _fmt(v))

        obs = self.observer
        pl = self.pipeline
        # configuration (static)
        conf = [kv("system", self.system.name), kv("fingerprint", self.system.fingerprint()[:16]),
                kv("gain_table", str(self.table_path)), kv("mode", self.mode),
                kv("cycles", " ".join(c.label() for c in self.cycles) or "robust"),
                kv("e0", obs.e0), kv("gain family", obs.family)]
        if obs.noise is not None:
            conf.append(kv("noise model", obs.noise.describe()))
        if obs.kalman is not None:
            conf += [kv("kalman", obs.kalman.describe())]
        for k, d in enumerate(obs.designs if obs.family == "lmi" else ()):
            conf.append(kv(f"design[{k}].eta", d.eta))
            conf.append(kv(f"design[{k}].kappa", d.kappa))
            conf.append(kv(f"design[{k}].f (paper factors)", d.f))
        # observer (dynamic)
        d = obs.current_design
        cyc = getattr(d, "cycle", None)
        ob = [kv("channel", obs.channel), kv("estimate time (s since origin)", obs.t),
              kv("current cycle tau", cyc.tau if cyc is not None else "robust"),
              kv("current cycle s", cyc.s if cyc is not None else "robust"),
              kv("current design index", obs.design_index),
              kv("updates", pl.updates), kv("partial updates", pl.partial_updates),
              kv("switches", pl.switches), kv("resets", pl.resets),
              kv("estimates withheld (non-finite, then reset)", pl.nonfinite), kv("internal errors", pl.errors),
              kv("clock jumps back (resets)", self.clock_jumps_back),
              kv("clock jumps forward", self.clock_jumps_forward)]
        if obs.family == "lmi":
            ob += [kv("current eta", d.eta), kv("current kappa", d.kappa),
                   kv("current gain norms |L_i|", [float(np.linalg.norm(L, 2)) for L in d.L])]
        if obs.kalman is not None:
            ob += [kv("kalman table departures (online recursion)", obs.kalman_departures),
                   kv("kalman table re-locks", obs.kalman_relocks),
                   kv("kalman gains now", obs.gains_source)]
            if obs.kalman_fallback:
                ob.append(kv("last kalman departure", obs.kalman_fallback))
        if self.last_clock_jump:
            ob.append(kv("last clock jump", self.last_clock_jump))
        recs = obs.completed_cycles
        if recs:
            r = recs[-1]
            ob += [kv("cycles completed", len(recs)), kv("last cycle measured tau", r.tau),
                   kv("last cycle measured s", r.s), kv("last cycle measured h", r.h),
                   kv("last cycle paper factors f", r.f), kv("last cycle matched schedule", r.matched)]
            if r.a2_ok is not None:
                ob.append(kv("last cycle A2 held", r.a2_ok))
        else:
            ob.append(kv("cycles completed", 0))
        res = pl.residence()
        if res is not None:
            ob += [kv("active channel residence (s)", res.current),
                   kv(f"designed residence (s, {res.kind})", [res.lo, res.hi]),
                   kv("residence violations", res.violations)]
            if res.last is not None:
                ob.append(kv("last residence (channel, s)", [res.last[0], res.last[1]]))
            if res.f is not None:
                ob.append(kv("cycle so far paper factors f", res.f))
        if pl.origin_ns is not None:
            env = obs.envelope()
            pl = self.pipeline
            ob += [kv("paper bound", env.paper_bound),
                   kv("exact bound", env.exact_bound if pl.bound_valid else "none (after a reset)"),
                   kv("exact bound valid", pl.bound_valid if pl.bound_valid else f"false ({pl.bound_invalid_why})")]
        level, msg = DiagnosticStatus.OK, "estimating"
        if pl.last_accept_clock_ns is None:
            level, msg = DiagnosticStatus.WARN, "waiting for measurements"
        else:
            age = (now_ns - pl.last_accept_clock_ns) * 1e-9
            ob.append(kv("seconds since last measurement", age))
            if age > self.sensor_timeout:
                level = DiagnosticStatus.WARN
                msg = f"no measurement for {age:.2f} s (sensor_timeout {self.sensor_timeout} s)"
            if age > self.sensor_timeout and self.last_prediction is not None \
                    and self.last_prediction.stamp_ns > (pl.obs_ns or 0):
                ob += [kv("outage: predicting (last innovation held), exact bound", self.last_prediction.exact_bound),
                       kv("outage predictions published", self.predictions)]
        if recs and not recs[-1].matched:
            level = max(level, DiagnosticStatus.WARN)
            msg += "; last cycle did not match the schedule"
        if res is not None and res.problem:
            level = max(level, DiagnosticStatus.WARN)
            msg += f"; {res.problem}"
        # inputs: rates over the last period (node clock), rejected totals by reason
        t0_ns, acc0, _ = self._rate_base
        dt = (now_ns - t0_ns) * 1e-9
        inp = []
        for topic in ("camera/pose", "target/pose", "camera/active_channel"):
            rate = (pl.accepted[topic] - acc0[topic]) / dt if dt > 0 else 0.0
            inp.append(kv(f"{topic} rate (Hz)", rate))
            inp.append(kv(f"{topic} accepted", pl.accepted[topic]))
        total_rej = sum(pl.rejected.values())
        for (topic, reason), n in sorted(pl.rejected.items()):
            inp.append(kv(f"rejected {topic} {reason}", n))
        inp.append(kv("rejected total", total_rej))
        if pl.last_rejection:
            inp.append(kv("last rejection", pl.last_rejection))
        new_rej = total_rej - self._rate_base[2]
        self._rate_base = (now_ns, Counter(pl.accepted), total_rej)
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
