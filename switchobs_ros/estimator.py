"""The estimator node: the switched Luenberger observer of switchobs_core on ROS 2 topics.

``ros2 run switchobs_ros estimator --ros-args --params-file config/estimator.yaml``

Thin glue (docs/architecture.md): parameters, topics, QoS, clocks, diagnostics. The estimation
is :class:`switchobs_core.runtime.observer.SwitchedObserver`; messages go through :mod:`msg_bridge`.

Input handling (validation, pairing, channel attribution, the observer, the counters) is
:class:`switchobs_ros.pipeline.EstimatorPipeline`, shared with the offline bag tools
(``switchobs_bag estimate``); this module is the rclpy glue around it: parameters,
subscriptions, publishing each estimate, the pairing timer (``pairing_timeout``, wall clock),
the clock-jump callback, ``~/reset`` and ``/diagnostics``.

Inputs (:mod:`switchobs_ros.attribution`): one subscription per source of the system's input specification
(:mod:`msg_bridge.inputs`; the paper interface ``camera/pose``, ``target/pose`` and
``camera/active_channel`` by default), each callback taking rclpy's ``MessageInfo``: the
publisher's source timestamp attributes a sample to the channel that was active when it was
sent, never the order in which the executor happened to serve the topics.

Time: observer time is ``(stamp - origin)`` in seconds, with ``origin`` the stamp of the first
sample accepted after start-up or a reset (integer nanoseconds until that subtraction).
Every output carries the stamp of the sample it answers.

Executor cost: each input callback also takes the input messages already waiting
(:meth:`EstimatorMixin._drain_inputs`), so a camera/target pair costs one wait of the executor,
not two, and a backlog none; publishers and subscriptions carry no default middleware event
handlers (each one a waitable that rclpy's executor re-adds on every wait), the subscriptions
keep the incompatible-QoS warning.

Clock jumps: a jump of the node clock backwards (with ``use_sim_time``, a looped bag restarting
its ``/clock``) resets the estimator, so the replay's samples are accepted again and the
estimate converges again; a jump forwards by more than ``sensor_timeout`` is counted. Both are
reported in ``/diagnostics``. Replays must therefore publish ``/clock`` (the bag tools do): stamps
that go back without the clock going back are rejected as ``old_stamp``, never silently used.
"""

from __future__ import annotations

import sys

if __name__ == "__main__":      # python -m switchobs_ros.estimator: the console script's start, participant first
    from switchobs_ros.entry import estimator as _console_script
    sys.exit(_console_script())

import math
import time
from collections.abc import Callable
from typing import Any

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray
from nav_msgs.msg import Odometry
from rcl_interfaces.msg import SetParametersResult
from rclpy.clock import Clock, ClockType, JumpThreshold, TimeJump
from rclpy.duration import Duration
from rclpy.event_handler import PublisherEventCallbacks, SubscriptionEventCallbacks
from rclpy.exceptions import InvalidHandle
from rclpy.node import Node
from rclpy.qos import qos_policy_name_from_kind
from std_msgs.msg import Float64MultiArray
from std_srvs.srv import Trigger
from switchobs_msgs.msg import ErrorBounds, StateEstimate

import msg_bridge as mb
from msg_bridge.raw import RawLabelledArrayWriter, RawOdometryBatch
from msg_bridge.typed import ErrorBoundsWriter, RawStateEstimateWriter

from . import qos
from .channel_input import CHANNEL_MSG, channel_type
from .config import PARAMS, EstimatorConfig, body_frame_prefix, check_runtime_value
from .demand import Demand
from .diagnostics import EstimatorDiagnostics, NodeState
from .log_callers import register_log_callers
from .outputs import OutputsMixin, channel_bodies
from .params import ConfigError, declare_all, unknown_parameters
from .pipeline import EstimatorPipeline, PipelineLog
from .runner import run_node

__all__ = ["PARAMS", "PREDICTION_BOUND_LABELS", "EstimatorNode", "main"]

#: Element names of ``~/prediction/bound``.
PREDICTION_BOUND_LABELS = ("exact_bound", "seconds_since_measurement")


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


class EstimatorMixin(OutputsMixin):
    """The estimator's behaviour on any rclpy node class (plain or lifecycle): configuration
    (:meth:`_configure`: the pipeline, the observer, the writers), the ROS interfaces
    (:meth:`_create_interfaces` / :meth:`_destroy_interfaces`), the callbacks. ``answering``
    gates the measurement callbacks (a deactivated managed node keeps its estimate and ignores
    measurements, counting them)."""

    answering = True
    ignored_inactive = 0
    _hot_inputs: tuple = ()

    def _ready_log(self) -> None:
        self.get_logger().info(
            f"estimator ready: system '{self.system.name}' (n={self.system.n}, N={self.system.N}), "
            f"mode {self.mode}, cycles {[c.label() for c in self.cycles]}, table {self.table_path}, "
            f"start-up {time.monotonic() - self.t_start:.2f} s")

    # ------------------------------------------------------------------ the optional outputs' writers
    def _optional_writer(self, kind: str, make: Callable[[], Any]) -> Any:
        """The writer of an optional output, serialised at its first use: an output nobody listens to
        costs nothing at start-up (the 33 odometries and the markers take 50-90 ms at n = 132). The
        same messages as a writer built in :meth:`_configure` (``test_lazy_writers.py``); the writers
        are built anew at every configuration."""
        w = self._writers.get(kind)
        if w is None:
            w = self._writers[kind] = make()
        return w

    @property
    def w_odom(self) -> RawOdometryBatch:
        """The bodies' odometries (``~/<body>/odom``)."""
        return self._optional_writer("odom", lambda: RawOdometryBatch(self.bodies, self.frame, self.child_frames))

    @property
    def w_typed(self) -> tuple[RawStateEstimateWriter, ErrorBoundsWriter]:
        """The typed outputs (switchobs_msgs: ``~/state_estimate``, ``~/error_bounds``)."""
        return self._optional_writer("typed", lambda: (RawStateEstimateWriter(self.state_labels, self.frame),
                                                       ErrorBoundsWriter(self.system.N, self.frame,
                                                                         self._noise_declared)))

    # ------------------------------------------------------------------ configuration
    def _configure(self, cfg: dict) -> None:
        # the input handling (validation, pairing, observer, counters) is the pipeline's
        conf = EstimatorConfig.from_values(cfg)     # every check of the values, in one place
        self.pipeline = pl = EstimatorPipeline.from_params(conf, _NodeLog(self.get_logger()))
        for topic in (pl.channel_topic, *(s.topic for s in pl.sources)):    # in this node's namespace
            why = mb.ros_topic_error(topic, self.get_namespace()) if topic else None
            if why:
                raise ConfigError(f"parameter 'inputs': topic {topic} in namespace {self.get_namespace()}: ROS: {why}")
        self.system = sys_ = pl.system
        self.mode = pl.mode
        self.cycles = pl.cycles
        self.table, self.table_path = pl.table, pl.table_path
        self.observer = pl.observer
        self.bodies = mb.bodies(sys_.state_labels)
        self.get_logger().info(mb.describe_bodies(sys_.state_labels))
        prefix = body_frame_prefix(cfg["frame_prefix"], self.get_namespace())     # one set of frames per robot
        self.child_frames = [prefix + c for c in conf.child_frames]
        self.state_labels = tuple(sys_.state_labels)
        self._noise_declared = pl.observer.noise_max is not None
        self.env_labels = mb.envelope_labels(sys_.N, noise_bound=self._noise_declared)
        self.frame = cfg["world_frame"]
        # the outputs' writers: serialised once, numbers rewritten in place (msg_bridge.raw); those of
        # the optional outputs (odometries, typed, markers) at their first use (_optional_writer)
        self.w_state = RawLabelledArrayWriter(self.state_labels)
        self.w_env = RawLabelledArrayWriter(self.env_labels)
        self._writers: dict[str, Any] = {}
        self.body_in_view = channel_bodies(sys_, self.bodies)
        self.pair_timeout = cfg["pairing_timeout"]
        self.sensor_timeout = cfg["sensor_timeout"]
        # output decimation (output.*_every; 0: never) and the runner's choices
        self.every = {k: int(cfg[f"output.{k}_every"]) for k in ("envelope", "odometry", "covariance", "typed",
                                                                  "markers")}
        self.n_published = 0
        # optional outputs, and P, only while someone listens (switchobs_ros.demand)
        self.covariance_allowed = pl.publish_covariance
        self.demand = Demand(self._covariance_carriers)
        pl.covariance_due = self._covariance_due    # P formed only for an estimate a listened output carrying it takes
        self.published = dict.fromkeys(("state", "envelope", "covariance", "odometry", "typed", "markers"), 0)
        self.gc_freeze = bool(cfg["gc_freeze"])
        self.diag = EstimatorDiagnostics(self.get_fully_qualified_name(), pl, self.get_clock().now().nanoseconds)

    def _create_interfaces(self) -> None:
        """Publishers, subscriptions, the ``~/reset`` service, the clock-jump callback and the timers."""
        pl, cfg = self.pipeline, self.cfg

        # Middleware events: rclpy gives every publisher and subscription two event handlers
        # by default (incompatible QoS, incompatible type), each a waitable that its
        # SingleThreadedExecutor adds to the wait set it rebuilds on every wait: 28 of them
        # here took the idle wait from 127 to 218 us (measured, bench/RESULTS.md). The
        # subscriptions keep the incompatible-QoS warning (a sensor or channel publisher whose
        # QoS does not match gets its messages silently dropped); a subscriber of our outputs
        # with incompatible QoS is warned on its own side. A publisher of another message type is
        # found in the graph instead (:meth:`_check_input_types`): the incompatible-type event
        # does not come between processes with rmw_fastrtps (measured), so it would be a waitable
        # that never fires.
        def pub(msg_type, topic, profile):
            return self.create_publisher(msg_type, topic, profile,
                                         event_callbacks=PublisherEventCallbacks(use_default_callbacks=False))

        def sub(msg_type, topic, callback, profile, raw=False):
            warn = self.get_logger().warn

            def incompatible(event, topic=topic):
                warn(f"a publisher on '{topic}' offers incompatible QoS (policy "
                     f"{qos_policy_name_from_kind(event.last_policy_kind)}): its messages are not received")
            events = SubscriptionEventCallbacks(incompatible_qos=incompatible, use_default_callbacks=False)
            return self.create_subscription(msg_type, topic, callback, profile, event_callbacks=events, raw=raw)

        # publishers (reliable), then subscriptions (sensor data; channel reliable). The
        # channel subscription is created first so that, when a channel message and a pose
        # are ready together, the executor takes the channel first.
        self.pub_state = pub(Float64MultiArray, "~/state", qos.OUTPUT)
        self.pub_env = pub(Float64MultiArray, "~/envelope", qos.OUTPUT)
        self.pub_cov = None
        if pl.publish_covariance:
            self.pub_cov = pub(Float64MultiArray, "~/covariance", qos.OUTPUT)
        self.pub_odom = [pub(Odometry, f"~/{b.name}/odom", qos.OUTPUT) for b in self.bodies]
        self.pub_typed = (pub(StateEstimate, "~/state_estimate", qos.OUTPUT),
                          pub(ErrorBounds, "~/error_bounds", qos.OUTPUT))
        self.pub_markers, self.markers_pending = None, bool(self.bodies)    # after the first estimate: late_markers
        self.pub_diag = pub(DiagnosticArray, "/diagnostics", qos.OUTPUT)
        # sensor outage: the prediction and its exact bound, once per diagnostics period, on
        # topics of their own (~/state stays one answer per measurement)
        self.pub_pred = pub(Float64MultiArray, "~/prediction", qos.OUTPUT)
        self.pub_pred_bound = pub(Float64MultiArray, "~/prediction/bound", qos.OUTPUT)
        self.w_pred_bound = mb.LabelledArrayWriter(PREDICTION_BOUND_LABELS)
        self.predictions = 0
        self.last_prediction = None
        # inputs (the system's input specification): the channel topic first, so that, when a
        # channel message and a pose are ready together, the executor takes the channel first
        # (attribution does not depend on it: source timestamps, switchobs_ros.attribution). A source
        # of a fixed layout is taken as serialised bytes and read without a message object
        # (msg_bridge.parse: the same checks as a message's)
        self._input_subs = []
        hot = []
        self.sub_channel, self._sub = None, sub     # the channel's: _channel_subscription
        for src in pl.sources:
            handle = self._input_handler(src.index)
            s = sub(mb.message_class(src.type), src.topic, self._with_drain(handle), qos.SENSOR_SUB, raw=src.raw)
            self._input_subs.append(s)
            hot.append((s, handle))
        self.sub_control = None
        if pl.control is not None:      # commands u, held from their stamps (switchobs_ros.control); reliable
            self.sub_control = sub(mb.message_class(pl.control.spec.type), pl.control.topic, self.control_callback,
                                   qos.CHANNEL_SUB)
        self.srv_reset = self.create_service(Trigger, "~/reset", self.reset_callback)
        self.sub_set_state = sub(Float64MultiArray, "~/set_state", self.set_state_callback, qos.CHANNEL_SUB)
        self._hot_inputs = tuple(hot)
        self._input_types = {s.topic: s.type for s in pl.sources}      # what each input topic must carry
        self._channel_subscription()
        self.clock_jumps_back = 0
        self.clock_jumps_forward = 0
        self.last_clock_jump = ""
        self._jump_handle = self.get_clock().create_jump_callback(
            JumpThreshold(min_forward=Duration(nanoseconds=int(self.sensor_timeout * 1e9)),
                          min_backward=Duration(nanoseconds=-1), on_clock_change=False),
            post_callback=self.clock_jump_callback)
        self.diag_timer = self.create_timer(cfg["diagnostics_period"], self.diagnostics_callback)
        # wall (steady) time: the pairing timeout and the reorder window count real waiting, and a
        # sim clock that stops (a replay's end) must not hold the last samples back
        self._steady = Clock(clock_type=ClockType.STEADY_TIME)
        self.pair_timer = self.create_timer(self._pairing_period(), self.pairing_callback, clock=self._steady)
        self._pair_armed = True

    def _channel_subscription(self) -> None:
        """The channel topic's subscription, of the type :func:`~switchobs_ros.channel_input.channel_type`
        gives, first among the hot inputs (taken first when a channel message and a pose are ready)."""
        topic = self.pipeline.channel_topic
        if not topic or (self.sub_channel is not None and self.pipeline.accepted[topic]):
            self._channel_tentative = False         # a channel message arrived: the type is settled
            return
        self._channel_tentative = self.cfg["channel_type"] == "auto"
        kind = channel_type(self, topic, self.cfg["channel_type"])
        if self.sub_channel is not None:
            if self._input_types.get(topic) == kind:
                return
            self._hot_inputs = tuple(h for h in self._hot_inputs if h[0] is not self.sub_channel)
            self.destroy_subscription(self.sub_channel)
        handle = self._input_handler(None)
        self.sub_channel = self._sub(CHANNEL_MSG[kind], topic, self._with_drain(handle), qos.CHANNEL_SUB)
        self._hot_inputs = ((self.sub_channel, handle), *self._hot_inputs)
        self._input_types[topic] = kind
        self.get_logger().info(f"channel topic '{topic}': {kind}")

    def _destroy_interfaces(self) -> None:
        """Undo :meth:`_create_interfaces` (managed node: cleanup and shutdown)."""
        for name in ("pub_state", "pub_env", "pub_cov", "pub_diag", "pub_pred", "pub_pred_bound", "pub_markers"):
            pub = getattr(self, name, None)
            if pub is not None:
                self.destroy_publisher(pub)
            setattr(self, name, None)
        for pub in [*getattr(self, "pub_odom", []), *getattr(self, "pub_typed", ())]:
            self.destroy_publisher(pub)
        self.pub_odom = []
        self.pub_typed = ()
        self._hot_inputs = ()
        for sub in getattr(self, "_input_subs", []):
            self.destroy_subscription(sub)
        self._input_subs = []
        for name in ("sub_channel", "sub_set_state", "sub_control"):
            sub = getattr(self, name, None)
            if sub is not None:
                self.destroy_subscription(sub)
            setattr(self, name, None)
        for name in ("diag_timer", "pair_timer"):
            tm = getattr(self, name, None)
            if tm is not None:
                self.destroy_timer(tm)
            setattr(self, name, None)
        if getattr(self, "srv_reset", None) is not None:
            self.destroy_service(self.srv_reset)
            self.srv_reset = None
        self._jump_handle = None

    # ------------------------------------------------------------------ inputs
    #: Input messages one callback takes from the input subscriptions (its own message not
    #: counted) before it returns to the executor (:meth:`_drain_inputs`).
    DRAIN_MAX = 32

    def _input_handler(self, index: int | None):
        """The handler of one input: ``handle(msg, info)`` with rclpy's MessageInfo ``info`` (its
        ``source_timestamp``, the publisher's clock: :mod:`switchobs_ros.attribution`,
        :mod:`switchobs_ros.clocks`); ``index`` None is the channel topic."""
        pipeline, now = self.pipeline, self.get_clock().handle.get_now     # rcl's time point: Clock.now() less its Time
        dds = f"{pipeline.channel_topic if index is None else pipeline.sources[index].topic} (DDS source timestamp)"

        def handle(msg, info) -> None:
            if not self.answering:
                self.ignored_inactive += 1
                return
            # the sequence number shows lost messages (switchobs_ros.loss; the channel's: attribution)
            src_ns, recv_ns, seq = (info.get("source_timestamp"), info.get("received_timestamp"),
                                    info.get("publication_sequence_number")) if info else (None, None, None)
            if src_ns:
                src_ns = int(src_ns)
                if recv_ns and (why := pipeline.clocks.seen(dds, src_ns, int(recv_ns), system=True)):
                    pipeline.withdraw(why)          # the sender's system clock against ours
            else:
                src_ns = None
            out = pipeline.on_channel(msg, src_ns=src_ns, seq=seq) if index is None \
                else pipeline.on_input(index, msg, now().nanoseconds, None, src_ns, seq)
            if out:
                self._publish_all(out)
        return handle

    def _with_drain(self, handle):
        """The subscription callback: the handler, then the inputs already waiting."""
        def callback(msg, info) -> None:
            handle(msg, info)
            self._drain_inputs()
        return callback

    def _drain_inputs(self) -> None:
        """Take the input messages already waiting (channel, camera, target: one of each per
        round, the channel first, as the executor orders them after one wait) and handle them,
        up to :attr:`DRAIN_MAX`; then the executor's queued entries of the inputs are dropped
        (``discard_ready``: each would cost an empty take; an input that holds a message again is
        reported by the next wait, rcl's wait being level-triggered).

        Every wait of the executor costs Python and middleware work (rclpy's
        SingleThreadedExecutor rebuilds its wait set for it, about 150 us for this node;
        :class:`~switchobs_ros.executor.KeptWaitSetExecutor`, the node's, keeps it: about a third
        of that; bench/RESULTS.md): the target pose that arrives while the camera
        pose is handled would cost one more wait, and a backlog one wait per message. Taking
        them here costs a few microseconds each. The bound keeps timers and services served. Then
        the pairing timer runs if a sample waits (:meth:`_arm_pairing_timer`).
        """
        hot = self._hot_inputs
        n = 0
        try:
            while n < self.DRAIN_MAX:
                took = n
                for sub, handle in hot:
                    try:
                        with sub.handle:
                            got = sub.handle.take_message(sub.msg_type, sub.raw)
                    except InvalidHandle:       # destroyed (managed node cleanup)
                        return
                    if got is not None:
                        handle(got[0], got[1])
                        n += 1
                if n == took:
                    break
            discard = getattr(getattr(self, "executor", None), "discard_ready", None)
            if discard is not None:
                discard(tuple(h[0] for h in self._hot_inputs))
            self._arm_pairing_timer()
        except Exception as err:
            self.pipeline.internal_error("input", err)

    def control_callback(self, msg: Any) -> None:
        """The control topic: a command ``u`` held from its stamp on (the pipeline's
        :meth:`~switchobs_ros.pipeline.EstimatorPipeline.on_control`)."""
        if not self.answering:
            self.ignored_inactive += 1
            return
        self.pipeline.on_control(msg, self.get_clock().now().nanoseconds)

    def set_state_callback(self, msg: Float64MultiArray) -> None:
        """``~/set_state``: set some or all entries of the estimate at a stamp (the pipeline's
        :meth:`~switchobs_ros.pipeline.EstimatorPipeline.on_set_state`)."""
        if not self.answering:
            self.ignored_inactive += 1
            return
        self.pipeline.on_set_state(msg, self.get_clock().now().nanoseconds)

    def _pairing_period(self) -> float:
        """Period of the pairing timer: half the pairing timeout or of the reorder window (>= 5 ms)."""
        window = self.pipeline.window_ns * 1e-9 if self.pipeline.channel_topic else math.inf
        return max(min(self.pair_timeout, window) / 2, 0.005)

    def pairing_callback(self) -> None:
        if self._channel_tentative:         # channel_type auto: until a channel message arrives
            self._channel_subscription()
        if self.answering:
            self._publish_all(self.pipeline.flush_overdue(time.monotonic(), self.pair_timeout))
        self._arm_pairing_timer()

    def _arm_pairing_timer(self) -> None:
        """The pairing timer runs only while it has work: a sample waits (for its partners or its
        channel) or the channel's type is not settled. A cancelled timer never wakes the executor;
        a running one wakes it every period (40 times a second by default), each wake a wait of
        rclpy's executor (bench/RESULTS.md, live at scale). Re-armed, it fires a period later."""
        need = bool(self.pipeline.pairing.pending) or self._channel_tentative
        if need != self._pair_armed and self.pair_timer is not None:
            if need:
                self.pair_timer.reset()
            else:
                self.pair_timer.cancel()
            self._pair_armed = need

    # ------------------------------------------------------------------ runtime parameters
    def set_parameters_atomically(self, parameter_list: list) -> SetParametersResult:
        """rclpy's, with the node's own line for a name it does not declare (the ``set_parameters``
        and ``set_parameters_atomically`` services come here; rclpy would answer ``Invalid access
        to undeclared parameter(s): []``)."""
        why = unknown_parameters([p.name for p in parameter_list], PARAMS, self.get_name())
        if why:
            return SetParametersResult(successful=False, reason=why)
        return super().set_parameters_atomically(parameter_list)

    def set_parameters(self, parameter_list: list) -> list:
        """rclpy's, one result per parameter; a name the node does not declare gets the node's own
        line instead of rclpy's exception (see :meth:`set_parameters_atomically`)."""
        if not unknown_parameters([p.name for p in parameter_list], PARAMS, self.get_name()):
            return super().set_parameters(parameter_list)
        return [self.set_parameters_atomically([p]) for p in parameter_list]

    def _on_set_parameters(self, params: list) -> SetParametersResult:
        """Accept the runtime parameters (``config.RUNTIME_PARAMS``) with valid values, refuse the
        rest with the reason; all or nothing."""
        for p in params:
            why = check_runtime_value(p.name, p.value)
            if why:
                return SetParametersResult(successful=False, reason=why)
        for p in params:
            self.cfg[p.name] = p.value
            if p.name.startswith("output."):
                self.every[p.name[len("output."):-len("_every")]] = int(p.value)
                self.demand.expire()
            elif p.name == "sensor_timeout":
                self.sensor_timeout = float(p.value)
            elif p.name == "future_tolerance":
                self.pipeline.future_ns = int(float(p.value) * 1e9)
            elif p.name == "max_abs_value":
                self.pipeline.max_abs = float(p.value)
            elif p.name == "pairing_timeout":
                self.pair_timeout = float(p.value)
                self.destroy_timer(self.pair_timer)
                self.pair_timer = self.create_timer(self._pairing_period(), self.pairing_callback,
                                                    clock=self._steady)
                self._pair_armed = True
            elif p.name == "diagnostics_period":
                self.destroy_timer(self.diag_timer)
                self.diag_timer = self.create_timer(float(p.value), self.diagnostics_callback)
            self.get_logger().info(f"parameter {p.name} set to {p.value!r}")
        return SetParametersResult(successful=True)

    # ------------------------------------------------------------------ reset
    def reset_estimator(self, why: str) -> None:
        """Back to the initial estimate (see :meth:`EstimatorPipeline.reset`)."""
        self._publish_all(self.pipeline.reset(why))

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
            self._check_input_types()
        except Exception as err:
            self.pipeline.internal_error("graph", err)
        try:
            self.pub_diag.publish(self.diagnostics())
        except Exception as err:
            self.pipeline.internal_error("diagnostics", err)

    def _check_input_types(self) -> None:
        """Publishers of another message type on an input topic (the ROS graph): none of their
        messages reach the node. Counted per topic (:mod:`switchobs_ros.loss`), in /diagnostics,
        and logged when their number changes."""
        for topic, ours in getattr(self, "_input_types", {}).items():
            name = self.resolve_topic_name(topic)
            theirs = sorted(i.topic_type for i in self.get_publishers_info_by_topic(name) if i.topic_type != ours)
            if self.pipeline.loss.wrong_type_seen(topic, len(theirs), ", ".join(dict.fromkeys(theirs))) and theirs:
                self.get_logger().warn(f"a publisher on '{name}' sends {', '.join(dict.fromkeys(theirs))}, not "
                                       f"{ours}: its messages are not received")

    def diagnostics(self) -> DiagnosticArray:
        """The /diagnostics message now (built by :class:`~switchobs_ros.diagnostics.EstimatorDiagnostics`)."""
        return self.diag.array(self.get_clock().now(), NodeState(
            self.clock_jumps_back, self.clock_jumps_forward, self.last_clock_jump, self.sensor_timeout,
            self.last_prediction, self.predictions, self.ignored_inactive))

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

class EstimatorNode(EstimatorMixin, Node):
    """Subscribes the camera topics, drives a SwitchedObserver, publishes the estimate."""

    def __init__(self, **kwargs):
        super().__init__("estimator", **kwargs)
        self.t_start = time.monotonic()
        register_log_callers(__name__)      # rclpy's first log line without a visit of every module
        cfg = declare_all(self, PARAMS, gated=True)
        self.cfg = cfg
        self._configure(cfg)
        self._create_interfaces()
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self._ready_log()


def main(args=None) -> int:
    return run_node(EstimatorNode, "estimator", args)

