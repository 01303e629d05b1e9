"""The estimator's input handling, without a node: validation, pairing, the observer, counters.

:class:`EstimatorPipeline` is what the estimator node runs on every message, and what the bag
tools run over a bag without DDS (``switchobs_bag estimate``), so the live node and the
offline run compute the same estimates from the same messages. It holds no rclpy node,
executor or publisher: the caller passes each incoming message with the node clock (``now_ns``)
and publishes (or writes) the :class:`Estimate` objects it gets back.

Measurement pairing
-------------------
Channel rho's output is ``y = [p_camera; p_target]``. ``camera/pose`` and ``target/pose``
arrive separately with (normally) the same header stamp: the pipeline keeps the pending samples
by stamp (up to :data:`MAX_PENDING`) and calls ``observer.update(t, rho, y)`` when both halves
are there. A half whose partner does not come (a newer pair completes, or the caller's
:meth:`EstimatorPipeline.flush_overdue` finds it older than ``pairing_timeout``) is used alone
through the observer's partial-rows input (``rows=``). The target pose is attributed to the
latest channel received on ``camera/active_channel`` (UInt8 has no stamp): a publisher must
send the new channel before the first target pose of that channel.

Dead time (``schedule.dead_time`` d > 0): after a switch the camera turns and only camera
poses come. From the first camera pose after a channel change (stamp ``s_0``) until the first
target pose of the new channel, a camera pose stamped before ``s_0 + d - (camera period)`` is
certainly blind (``s_0`` is at most one period after the switching instant) and is used alone
at once instead of waiting for a partner; one near the end of the dead time waits as usual.

Time: observer time is ``(stamp - origin)`` in seconds, with ``origin`` the stamp of the first
sample accepted after start-up or a reset (integer nanoseconds until that subtraction).
Every estimate carries the stamp of the sample it answers.

Failure behaviour (the table is in README.md, "Failure behaviour")
-------------------------------------------------------------------
* Every message is validated (:mod:`msg_bridge.validate`); a rejected one is counted under
  ``(topic, reason)`` and changes nothing else. A target pose stamped at or before the newest
  target pose received before the latest channel change is ``stale_after_switch``: it was taken
  while the previous channel was active (the channel message has no stamp, so this is all the
  node knows of the switching instant; camera poses do not depend on the channel, so a camera
  pose that DDS delivers before the channel message of the same tick changes nothing).
* Any exception while handling a message is caught, counted (``internal_error``) and logged;
  an estimate that is not finite is never returned (the estimator resets instead).
* Residence times are measured from the sample stamps at every switch and compared with
  what the gains were designed for: ``[h_min, h_max]`` (assumption A2) in robust mode, the
  scheduled ``h_i +- match_tol`` otherwise (:meth:`EstimatorPipeline.residence`). A channel that
  stays longer, or a switch that comes sooner, is reported with the measured time and the
  paper's factors of the cycle so far; the estimate keeps going with the gains it has.
* Without samples, :meth:`EstimatorPipeline.predict` gives the observer's prediction at a
  later time (what the next update will propagate: the last innovation held) and its exact
  bound ``||Phi(t, t0)|| e0``, which grows honestly with the outage.
"""

from __future__ import annotations

import math
import time
import traceback
from collections import Counter
from dataclasses import dataclass
from typing import Any

import numpy as np
from geometry_msgs.msg import PoseStamped
from std_msgs.msg import UInt8

import msg_bridge as mb
from msg_bridge import Reason, Rejection
from switchobs_core.cycles import Residence
from switchobs_core.exceptions import SwitchobsError
from switchobs_core.observer import SwitchedObserver

from .config import EstimatorConfig
from .core_config import load_or_design_table
from .params import ConfigError

__all__ = ["CHANNEL_TOPIC", "INPUT_TOPICS", "MAX_PENDING", "NO_BOUND", "POSE_TOPICS", "Estimate", "EstimatorPipeline",
           "PipelineLog", "Prediction", "Residence"]

PARTS = ("camera", "target")
#: ``exact_bound`` published after a reset: no bound is known any more. ``||Phi(t, t0)|| e0`` holds
#: only if ``||x_hat(t0) - x(t0)|| <= e0`` at the time origin; the configured ``e0`` is the user's
#: claim for the start, but after a reset (``~/reset``, a clock jump back, a non-finite estimate)
#: the plant has moved on and nothing bounds the new initial error. -1 is finite (the node never
#: publishes non-finite values) and cannot be a norm bound.
NO_BOUND = -1.0
#: Input topic of each pose part, and of the channel (relative names, as the node subscribes).
POSE_TOPICS = {"camera": "camera/pose", "target": "target/pose"}
CHANNEL_TOPIC = "camera/active_channel"
#: The set-state input's name in the counters (robot_localization's set_pose analogue).
SET_STATE_TOPIC = "~/set_state"
INPUT_TOPICS = (POSE_TOPICS["camera"], POSE_TOPICS["target"], CHANNEL_TOPIC)
#: Samples kept waiting for their other half (a backlog reorders the two topics a little).
MAX_PENDING = 8


@dataclass(frozen=True)
class Prediction:
    """The observer's prediction at a time with no sample (sensor outage).

    ``x_hat`` is what the observer will have propagated to ``stamp_ns`` when the next sample
    comes (the last innovation held); ``exact_bound`` is ``||Phi(t, t0)|| e0`` of that
    prediction (verified, like ``~/envelope``'s); ``age`` is the time since the last accepted
    measurement (node clock, s).
    """

    stamp_ns: int
    x_hat: np.ndarray
    exact_bound: float
    age: float


@dataclass(frozen=True)
class Estimate:
    """One observer update: the stamp it answers, ``x_hat``, the envelope values and the
    error covariance ``P`` (None when not published).

    ``envelope`` is ``[z_1..z_N, paper_bound, exact_bound]`` (the ``~/envelope`` layout).
    """

    stamp_ns: int
    x_hat: np.ndarray
    envelope: np.ndarray
    P: np.ndarray | None = None


class PipelineLog:
    """Where the pipeline reports: ``info``/``warn``/``error`` (text, throttle).

    ``throttle`` marks messages that may repeat at the input rate (the node throttles them to
    one per second). The default discards everything (offline use).
    """

    def info(self, text: str) -> None:
        pass

    def warn(self, text: str, throttle: bool = False) -> None:
        pass

    def error(self, text: str, throttle: bool = False) -> None:
        pass


class _Pending:
    """One sample being assembled: the halves that have arrived for one stamp."""

    __slots__ = ("channel", "since", "stamp_ns", "xy")

    def __init__(self, stamp_ns: int, since: float):
        self.stamp_ns = stamp_ns
        self.xy: dict[str, np.ndarray] = {}
        self.channel = 0
        self.since = since


class EstimatorPipeline:
    """Validation, pairing and the switched observer for the estimator's three input topics.

    Build it with :meth:`from_params` (the estimator's parameter values). Feed it with
    :meth:`on_channel` and :meth:`on_pose`; both return the estimates they produced (possibly
    none), in stamp order.

    Counters (never cleared, reported in diagnostics): ``accepted`` (per input topic),
    ``rejected`` (per ``(topic, reason)``), ``updates``, ``partial_updates``, ``switches``,
    ``resets``, ``errors``; ``last_rejection`` is the latest rejection's text.
    """

    def __init__(self, system, table, observer, *, x0: np.ndarray, rows, input_frame_id: str = "map",
                 max_abs: float = 1.0e6, future_tolerance_ns: int = 500_000_000,
                 log: PipelineLog | None = None, table_path: Any = None, mode: str = "periodic",
                 cycles: list | None = None):
        self.system = system
        self.table = table
        self.table_path = table_path
        self.mode = mode
        self.cycles = list(cycles or [])
        self.observer = observer
        self.x0 = np.array(x0, dtype=float)
        self.rows = rows
        self.in_frame = input_frame_id
        self.max_abs = max_abs
        self.future_ns = int(future_tolerance_ns)
        self.log = log or PipelineLog()
        self.N = system.N
        # run-time state (cleared by reset)
        self.channel = 0
        self.last_ns: dict[str, int | None] = {p: None for p in PARTS}
        self.pending: dict[int, _Pending] = {}   # by stamp (ns)
        self.origin_ns: int | None = None
        self.obs_ns: int | None = None           # stamp of the last observer update
        self.last_accept_clock_ns: int | None = None
        self.switch_ns: int | None = None        # newest pose stamp before the latest channel change
        self.dead_ns = int(round(max((c.dead_time for c in self.cycles), default=0.0) * 1e9))
        self.blind_first_ns: int | None = None  # first camera stamp after a channel change (dead time)
        self.target_since_switch = False
        self.cam_period_ns = 0                   # the latest gap between accepted camera stamps
        # counters (never cleared)
        self.accepted: Counter = Counter()
        self.rejected: Counter = Counter()
        self.updates = 0
        self.partial_updates = 0
        self.switches = 0
        self.resets = 0
        self.states_set = 0
        self.bound_valid = True     # False after any reset: see NO_BOUND
        self.bound_invalid_why = ""
        self.errors = 0
        self.nonfinite = 0          # estimates withheld because not finite (each followed by a reset)
        self.publish_covariance = bool(observer.track_covariance)   # Estimate.P (from_params: the parameter)
        self.last_rejection = ""

    # ------------------------------------------------------------------ construction
    @classmethod
    def from_params(cls, cfg: dict | EstimatorConfig, log: PipelineLog | None = None) -> EstimatorPipeline:
        """The pipeline of the estimator's configuration (an :class:`~switchobs_ros.config.EstimatorConfig`,
        or parameter values by name, checked into one).

        Loads the gain table (designing and caching one if ``gain_table`` is empty: LMI gains, or
        Kalman gains with ``gain_family: kalman``) and builds the observer. Raises
        :class:`~switchobs_ros.params.ConfigError` with one line on any bad value.
        """
        conf = cfg if isinstance(cfg, EstimatorConfig) else EstimatorConfig.from_values(cfg)
        log = log or PipelineLog()
        sys_, mode, cycles, family = conf.system, conf.mode, list(conf.cycles), conf.family
        table, table_path = load_or_design_table(
            conf["gain_table"], conf["gain_table_cache_dir"], sys_, mode, cycles, conf.robust, conf["delta"],
            log.info, family="kalman" if family == "kalman" else "lmi", rate=conf.rate, noise=conf.noise)
        if family in ("lmi", "kalman") and table.family != family:
            raise ConfigError(f"parameter 'gain_family' is '{family}' but the gain table holds {table.family} gains")
        try:
            fam = "kalman-online" if family == "kalman-online" else None
            lmi = table.family == "lmi" and fam is None
            # the kalman table brings its own noise model; the LMI covariance is tracked only if published
            observer = SwitchedObserver(sys_, table, mode=mode, cycles=cycles or None, x0=conf.x0, t0=0.0,
                                        e0=conf["e0"], bounds=conf.robust, family=fam,
                                        noise=None if table.family == "kalman" and fam is None else conf.noise,
                                        track_covariance=conf.publish_covariance if lmi else None,
                                        noise_max=conf.noise_max)
        except SwitchobsError as err:
            raise ConfigError(f"observer: {err}") from None
        pipe = cls(sys_, table, observer, x0=conf.x0, rows=list(conf.rows), input_frame_id=conf["input_frame_id"],
                   max_abs=conf["max_abs_value"], future_tolerance_ns=int(conf["future_tolerance"] * 1e9),
                   log=log, table_path=table_path, mode=mode, cycles=cycles)
        pipe.publish_covariance = conf.publish_covariance
        pipe.config = conf
        return pipe

    # ------------------------------------------------------------------ inputs
    def on_channel(self, msg: UInt8) -> None:
        """A ``camera/active_channel`` message: validate, count, remember the channel."""
        try:
            rej = mb.check_channel(msg, self.N)
            if rej is not None:
                self.reject(CHANNEL_TOPIC, rej)
                return
            self.accepted[CHANNEL_TOPIC] += 1
            c = int(msg.data)
            if c != self.channel:
                if self.channel:
                    self.switches += 1
                self.channel = c
                # camera poses do not depend on the channel; target poses up to this stamp
                # were taken while the previous channel was active
                if self.last_ns["target"] is not None:
                    self.switch_ns = self.last_ns["target"]
                self.blind_first_ns = None
                self.target_since_switch = False
        except Exception as err:
            self.internal_error(CHANNEL_TOPIC, err)

    def on_set_state(self, msg: Any, now_ns: int) -> bool:
        """A ``~/set_state`` message (robot_localization's ``set_pose``): a labelled array (the
        layout of ``~/state``) naming some state entries (``agent1.p_x``) and optionally their
        variances (``var:agent1.p_x``), stamped with the time they hold at. The observer
        propagates to the stamp and takes the values (:meth:`SwitchedObserver.set_estimate`);
        before the first sample they replace entries of the initial estimate. The exact bound is
        withdrawn (:data:`NO_BOUND`: the set entries' error is unknown) until the next reset.
        A bad message is rejected and counted; True when applied."""
        topic = SET_STATE_TOPIC
        try:
            try:
                arr = mb.unpack_labelled(msg)
            except mb.BridgeError as err:
                self.reject(topic, mb.Rejection(mb.Reason.BAD_LAYOUT, "layout", str(err)))
                return False
            index = {lab: i for i, lab in enumerate(self.system.state_labels)}
            values, variances = {}, {}
            for lab, v in zip(arr.labels, arr.values):
                name = lab[4:] if lab.startswith("var:") else lab
                if name not in index:
                    self.reject(topic, mb.Rejection(mb.Reason.BAD_LAYOUT, lab, "not a state entry (the labels of "
                                                    f"~/state, or var:<label>): {', '.join(index)}"))
                    return False
                if not np.isfinite(v):
                    self.reject(topic, mb.Rejection(mb.Reason.NON_FINITE, lab, f"{v}"))
                    return False
                if abs(v) > self.max_abs or (lab.startswith("var:") and v < 0):
                    self.reject(topic, mb.Rejection(mb.Reason.TOO_LARGE, lab, f"{v} (|v| <= {self.max_abs:g}, "
                                                    "variances >= 0)"))
                    return False
                (variances if lab.startswith("var:") else values)[index[name]] = float(v)
            if not values and not variances:
                self.reject(topic, mb.Rejection(mb.Reason.BAD_LAYOUT, "labels", "names no state entry"))
                return False
            if arr.stamp_ns - now_ns > self.future_ns:
                ahead = (arr.stamp_ns - now_ns) * 1e-9
                self.reject(topic, mb.Rejection(mb.Reason.FUTURE_STAMP, "stamp",
                                                f"{ahead:.3g} s ahead of the node clock"))
                return False
            if self.origin_ns is None:          # before the first sample: the initial estimate
                for i, v in values.items():
                    self.x0[i] = v
                self.observer.reset(self.x0, 0.0)
            else:
                if self.obs_ns is not None and arr.stamp_ns < self.obs_ns:
                    self.reject(topic, mb.Rejection(mb.Reason.OLD_STAMP, "stamp", "before the last estimate (the "
                                                    "past cannot be set)"))
                    return False
                self.observer.set_estimate((arr.stamp_ns - self.origin_ns) * 1e-9, values, variances)
                self.obs_ns = arr.stamp_ns
            self.accepted[topic] += 1
            self.states_set += 1
            self.bound_valid = False
            self.bound_invalid_why = "state set by ~/set_state"
            self.log.info(f"state set at stamp {arr.stamp_ns} ({', '.join(arr.labels)}); exact_bound is "
                          f"{NO_BOUND:g} (no bound known) from now on")
            return True
        except Exception as err:
            self.internal_error(topic, err)
            return False

    def on_pose(self, part: str, msg: PoseStamped, now_ns: int, now_mono: float | None = None) -> list[Estimate]:
        """A pose of ``part`` (``"camera"`` or ``"target"``) received at node-clock ``now_ns``.

        ``now_mono`` (default ``time.monotonic()``) starts the pairing timeout of a new
        pending sample. Returns the estimates produced (none while waiting for the other half).
        """
        topic = POSE_TOPICS[part]
        out: list[Estimate] = []
        try:
            rej = mb.check_pose(msg, frame_id=self.in_frame, max_abs=self.max_abs, last_ns=self.last_ns[part],
                                now_ns=now_ns, future_tolerance_ns=self.future_ns)
            stamp_ns = mb.stamp_to_ns(msg.header.stamp)
            if rej is None and not self.channel:
                rej = Rejection(Reason.NO_CHANNEL, CHANNEL_TOPIC, "no active channel received yet")
            if part == "target" and (rej is None or rej.reason in (Reason.OLD_STAMP, Reason.DUPLICATE_STAMP)):
                rej = mb.check_after_switch(stamp_ns, self.switch_ns) or rej   # the more specific reason
            if rej is None and self.obs_ns is not None and stamp_ns <= self.obs_ns:
                rej = Rejection(Reason.OLD_STAMP, "header.stamp",
                                f"not newer than the estimate ({(self.obs_ns - stamp_ns) * 1e-9:.6f} s older)")
            if rej is not None:
                self.reject(topic, rej)
                return out
            self.accepted[topic] += 1
            if part == "camera" and self.last_ns["camera"] is not None:
                self.cam_period_ns = stamp_ns - self.last_ns["camera"]
            elif part == "target":
                self.target_since_switch = True
            self.last_ns[part] = stamp_ns
            self.last_accept_clock_ns = now_ns
            pend = self.pending.get(stamp_ns)
            if pend is None:
                pend = self.pending[stamp_ns] = _Pending(stamp_ns, time.monotonic() if now_mono is None else now_mono)
                if len(self.pending) > MAX_PENDING:      # the oldest half's partner is overdue
                    self._flush(min(self.pending), out)
            pend.xy[part] = mb.pose_to_xy(msg)
            if part == "target" or not pend.channel:
                pend.channel = self.channel
            if len(pend.xy) == 2 or (part == "camera" and self._certainly_blind(stamp_ns)):
                # older samples will not be completed now: use their halves alone, in order
                for s_old in sorted(s for s in self.pending if s < stamp_ns):
                    self._flush(s_old, out)
                self._flush(stamp_ns, out)
        except Exception as err:
            self.internal_error(topic, err)
        return out

    def _certainly_blind(self, stamp_ns: int) -> bool:
        """Whether a camera pose at ``stamp_ns`` lies in the dead time for sure (module docstring)."""
        if not self.dead_ns or self.target_since_switch:
            return False
        if self.blind_first_ns is None:
            self.blind_first_ns = stamp_ns
        return stamp_ns - self.blind_first_ns < self.dead_ns - self.cam_period_ns

    def flush_overdue(self, now_mono: float, timeout: float) -> list[Estimate]:
        """Use alone the pending halves that waited longer than ``timeout`` (s, monotonic clock)."""
        out: list[Estimate] = []
        try:
            for s in sorted(self.pending):
                if now_mono - self.pending[s].since <= timeout:
                    break
                self._flush(s, out)
        except Exception as err:
            self.internal_error("pairing", err)
        return out

    def flush_all(self) -> list[Estimate]:
        """Use every pending half now, in stamp order (end of a bag)."""
        out: list[Estimate] = []
        try:
            for s in sorted(self.pending):
                self._flush(s, out)
        except Exception as err:
            self.internal_error("pairing", err)
        return out

    def _flush(self, stamp_ns: int, out: list[Estimate]) -> None:
        """Run the observer on a pending sample (both halves, or one alone); append the estimate."""
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
        dt = t - self.observer.t
        with np.errstate(all="ignore"):     # an overflow is caught below, not warned about
            violations = self.observer.residence_violations
            x_hat = self.observer.update(t, c, y, rows=rows)
            self.obs_ns = pend.stamp_ns
            self.updates += 1
            if rows is not None:
                self.partial_updates += 1
            try:
                env = self.observer.envelope()
                env_vals = np.concatenate([env.z, [env.paper_bound, env.exact_bound]]
                                          + ([] if env.noise_bound is None else [[env.noise_bound]]))
            except (np.linalg.LinAlgError, ArithmeticError, ValueError):
                # e.g. the SVD of an overflowed Phi
                env_vals = np.full(self.N + 2 + (self.observer.noise_max is not None), np.nan)
        if not (np.isfinite(x_hat).all() and np.isfinite(env_vals).all()):
            # e.g. a gap so long that the exact step of an unstable system overflows: never
            # publish it; start again from the initial estimate at the next sample
            self.errors += 1
            self.nonfinite += 1
            self.log.error(f"non-finite estimate at stamp {pend.stamp_ns} (step of {dt:.6g} s): not published; "
                           "resetting the estimator")
            self.reset("non-finite estimate")
            return
        if self.observer.residence_violations != violations:     # the residence that ended at t
            self.log.warn(self.observer.residence_problem, throttle=True)
        if not self.bound_valid:
            env_vals[self.N + 1:] = NO_BOUND      # exact_bound (and noise_bound)
        P = self.observer.P if self.publish_covariance else None
        if P is not None and not np.isfinite(P).all():
            P = None
        out.append(Estimate(pend.stamp_ns, np.array(x_hat, dtype=float), env_vals, P))

    # ------------------------------------------------------------------ bookkeeping
    def reject(self, topic: str, rej: Rejection) -> None:
        """Count a rejected message under ``(topic, reason)``."""
        self.rejected[(topic, rej.reason.value)] += 1
        self.last_rejection = f"{topic}: {rej}"
        self.log.warn(f"rejected {topic}: {rej}", throttle=True)

    def internal_error(self, where: str, err: Exception) -> None:
        """Count an exception raised while handling an input (the caller keeps running)."""
        self.errors += 1
        self.rejected[(where, "internal_error")] += 1
        self.last_rejection = f"{where}: internal_error: {type(err).__name__}: {err}"
        tb = traceback.extract_tb(err.__traceback__)
        at = f" (at {tb[-1].filename.rsplit('/', 1)[-1]}:{tb[-1].lineno})" if tb else ""
        self.log.error(f"{where}: {type(err).__name__}: {err}{at}", throttle=True)

    def reset(self, why: str) -> None:
        """Back to the initial estimate; the next accepted sample becomes the new time origin.

        Clears the pending samples and the per-topic stamp history (so a replay that starts
        over is accepted); keeps the active channel and all counters.
        """
        self.pending = {}
        self.origin_ns = None
        self.obs_ns = None
        self.last_ns = {p: None for p in PARTS}
        self.switch_ns = None
        self.blind_first_ns = None
        self.target_since_switch = False
        self.observer.reset(self.x0, 0.0)
        self.resets += 1
        self.bound_valid = False
        self.bound_invalid_why = why
        self.log.info(f"estimator reset ({why}); exact_bound is {NO_BOUND:g} (no bound known) from now on")


    # ------------------------------------------------------------------ residence times (A2)
    @property
    def residence_violations(self) -> int:
        """Residences outside what the gains were designed for (the observer counts them)."""
        return self.observer.residence_violations

    def residence(self) -> Residence | None:
        """The active channel's residence against the design (None before the first sample)."""
        return self.observer.residence()

    # ------------------------------------------------------------------ outage prediction
    def predict(self, now_ns: int) -> Prediction | None:
        """The observer's prediction for node-clock time ``now_ns``.

        The prediction is for the stamp ``obs_ns + (now_ns - last_accept_clock_ns)``: the last
        sample's stamp advanced by the node-clock time elapsed since the last accepted
        measurement, so a fixed offset between header stamps and the node clock (latency, a
        replay without ``/clock``) does not matter. None before the first sample, when no time
        has elapsed, or when the prediction is not representable (a very long outage of an
        unstable system overflows). The observer's state is not changed.
        """
        if self.origin_ns is None or self.obs_ns is None or self.last_accept_clock_ns is None:
            return None
        elapsed = now_ns - self.last_accept_clock_ns
        if elapsed <= 0:
            return None
        stamp = self.obs_ns + elapsed
        t = (stamp - self.origin_ns) * 1e-9
        try:
            with np.errstate(all="ignore"):
                x = self.observer.predict(t, hold=True)
                bound = self.observer.envelope(t).exact_bound
        except (SwitchobsError, ArithmeticError, ValueError, np.linalg.LinAlgError):
            return None
        if not (np.isfinite(x).all() and math.isfinite(bound)):
            return None
        return Prediction(int(stamp), x, float(bound) if self.bound_valid else NO_BOUND, elapsed * 1e-9)
