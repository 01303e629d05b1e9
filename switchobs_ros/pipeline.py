"""The estimator's input handling, without a node: a message in, the estimates it produces out.

:class:`EstimatorPipeline` is what the estimator node runs on every message, and what
``switchobs_bag estimate`` runs over a bag, so the live node and the offline run compute the same
estimates from the same messages. The caller passes each message with the node clock
(``now_ns``) and, when the middleware gives them, the publisher's source timestamp (``src_ns``)
and sequence number (``seq``), and publishes (or writes) the :class:`Estimate` objects it gets back.

For every message the pipeline orchestrates:

1. validation (:meth:`Source.checked <switchobs_ros.sources.Source.checked>`): a rejected
   message is counted under ``(topic, reason)`` and changes nothing else;
2. pairing (:mod:`switchobs_ros.pairing`): the sources' parts with one stamp form a sample;
3. channel attribution (:mod:`switchobs_ros.attribution`): the channel the sample was sent on,
   from the publisher's source timestamps and sequence numbers, never guessed;
4. screening (:mod:`switchobs_ros.screening`): the model against the data, with the core's
   innovation test against the published bound (a sample it refuses is re-attributed, or
   rejected and every bound withdrawn: :data:`NO_BOUND` until re-certified) or its chi-square gate;
5. the switched observer (e:switched_observer): ``SwitchedObserver.update`` with the sample's
   :class:`~switchobs_core.model.measurement.Measurement`, and an :class:`Estimate` with the envelope
   (the paper's envelopes and bound, the exact bound).

Observer time is ``(stamp - origin)`` in seconds, with ``origin`` the stamp of the first sample
answered after start-up or a reset; every estimate carries the stamp of the sample it answers.
An exception while handling a message is caught and counted (``internal_error``); an estimate
that is not finite is never returned (the estimator resets instead); a bound that can no longer
be computed (the observer's ``bounds_withdrawn``) withdraws the bounds with that reason while the
estimate is answered as usual. While no bound is published the observer's rigorous sets rest (its
``bounds_withdrawn`` set): a re-certification or a reset starts them afresh. The failure table is docs/failures.md.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Any

import numpy as np
from geometry_msgs.msg import PoseStamped

import msg_bridge as mb
from msg_bridge import Reason, Rejection
from switchobs_core.exceptions import SwitchobsError
from switchobs_core.families import family_entry, family_of_table
from switchobs_core.model.measurement import Measurement
from switchobs_core.runtime.cycles import Residence
from switchobs_core.runtime.observer import SwitchedObserver

from .attribution import ChannelAttribution, Resolution, Verdict
from .clocks import ClockWatch
from .config import UNCHECKED, EstimatorConfig
from .control import ControlInput
from .core_config import load_or_design_table
from .counters import NO_BOUND, Counters, PipelineLog
from .loss import SequenceLoss
from .pairing import MAX_PENDING, DeadTime, Pairing, Pending
from .params import ConfigError
from .screening import Screening
from .set_state import apply_set_state
from .sources import Source, sources_from_specs

__all__ = ["CHANNEL_TOPIC", "INPUT_TOPICS", "MAX_PENDING", "NO_BOUND", "POSE_TOPICS", "Estimate",
           "EstimatorPipeline", "PipelineLog", "Prediction", "Residence", "Source", "sources_from_specs"]

#: The paper interface's topics (the default input specification; relative names).
POSE_TOPICS = {"camera": "camera/pose", "target": "target/pose"}
CHANNEL_TOPIC = "camera/active_channel"
INPUT_TOPICS = (POSE_TOPICS["camera"], POSE_TOPICS["target"], CHANNEL_TOPIC)


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
    """One observer update: the stamp it answers, ``x_hat``, the envelope values, the error
    covariance ``P`` (None when not published) and the channel the sample was used on.

    ``envelope`` is ``[z_1..z_N, paper_bound, exact_bound(, noise_bound)]`` (the ``~/envelope``
    layout; the bounds -1 when withdrawn).
    """

    stamp_ns: int
    x_hat: np.ndarray
    envelope: np.ndarray
    P: np.ndarray | None = None
    channel: int = 0


class EstimatorPipeline(Counters):
    """Validation, pairing, attribution, the model against the data and the switched observer
    for the estimator's inputs (module docstring).

    Build it with :meth:`from_params` (the estimator's parameter values). Feed it with
    :meth:`on_message` (any input topic), or :meth:`on_channel` / :meth:`on_input`; each returns
    the estimates it produced (possibly none), in stamp order. Its counters are those of
    :class:`~switchobs_ros.counters.Counters`, with ``late_channel`` and ``lost_channel`` of the
    attribution.
    """

    def __init__(self, system, table, observer, *, x0: np.ndarray, sources: list[Source],
                 channel_topic: str | None = CHANNEL_TOPIC, input_frame_id: str = "map",
                 max_abs: float = 1.0e6, future_tolerance_ns: int = 500_000_000, log: PipelineLog | None = None,
                 table_path: Any = None, mode: str = "periodic", cycles: list | None = None,
                 reorder_window_ns: int = 50_000_000, check: bool = False, specs_text: str = "",
                 chi2_alpha: float = 0.0, control: Any = None, transforms: dict | None = None,
                 clock_tolerance_ns: int = 0):
        super().__init__(log or PipelineLog())
        self.system = system
        self.table = table
        self.table_path, self.mode, self.cycles = table_path, mode, list(cycles or [])
        self.observer = observer
        self.x0 = np.array(x0, dtype=float)
        self.sources = tuple(sources)
        self.by_topic = {s.topic: s for s in self.sources}
        self.channel_topic = channel_topic
        self.specs_text = specs_text
        self.in_frame = input_frame_id
        self.transforms = dict(transforms or {})     # input_transforms: {frame: FrameTransform}
        self.max_abs = max_abs
        self.future_ns = int(future_tolerance_ns)
        self.N = system.N
        # the parts: pairing, attribution, the dead time, the model against the data
        self.pairing = Pairing(self.sources, tuple(int(p) for p in system.p), clock_tolerance_ns)
        self.attribution = ChannelAttribution(self.sources, channel_topic, reorder_window_ns, clock_tolerance_ns)
        self.clocks = ClockWatch(clock_tolerance_ns)    # each source's stamps against the receive clock
        if clock_tolerance_ns and observer.rounding is not None:    # stamp errors in the bounds
            observer.rounding.clock(clock_tolerance_ns * 1e-9)
        self.dead_time = DeadTime(int(round(max((c.dead_time for c in self.cycles), default=0.0) * 1e9)),
                                  next((s.index for s in self.sources if s.shared), None))
        self.screening = Screening(system, observer, self.pairing, self, check=check, chi2_alpha=chi2_alpha)
        self.loss = SequenceLoss()               # messages the publishers' numbers show never arrived
        self.control = None if control is None else ControlInput(control)     # commands u (switchobs_ros.control)
        # run-time state (cleared by reset)
        self.last_ns: dict[str, int | None] = {s.topic: None for s in self.sources}
        self.origin_ns: int | None = None
        self.obs_ns: int | None = None           # stamp of the last observer update
        self.last_accept_clock_ns: int | None = None
        self.publish_covariance = bool(observer.track_covariance)   # Estimate.P (from_params: the parameter)
        self.covariance_due = lambda i: True     # P of a call's i-th estimate needed (the node: an output due)
        self.uncovered: tuple[int, ...] = ()     # channels no source feeds (from_params: the specification's)

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
        # the table a family reads ('' = the table's own family, LMI when one is designed)
        design = family_entry(family).table if family else "lmi"
        table, table_path = load_or_design_table(
            conf["gain_table"], conf["gain_table_cache_dir"], sys_, mode, cycles, conf.robust, conf["delta"],
            log.info, family=design, rate=conf.rate, noise=conf.noise, warn=log.warn, ahead=conf.table_ahead)
        if family and family_entry(family).stored and table.family != family:
            raise ConfigError(f"parameter 'gain_family' is '{family}' but the gain table holds {table.family} gains")
        try:
            # a family whose table brings its noise model takes none; the LMI covariance is tracked
            # only if published (the Kalman families always keep theirs)
            own_noise = family_entry(family or family_of_table(table)).rate
            observer = SwitchedObserver(sys_, table, mode=mode, cycles=cycles or None, x0=conf.x0, t0=0.0,
                                        e0=conf.e0, bounds=conf.robust, family=family or None,
                                        noise=None if own_noise else conf.noise,
                                        track_covariance=conf.publish_covariance,
                                        noise_max=conf.noise_max, disturbance=conf.disturbance, bound=conf["bound"])
        except SwitchobsError as err:
            raise ConfigError(f"observer: {err}") from None
        check = conf["consistency.check"] != "never"      # on whenever a bound is published (auto, always)
        pipe = cls(sys_, table, observer, x0=conf.x0, sources=sources_from_specs(conf.inputs, sys_),
                   channel_topic=conf.inputs.channel_topic, input_frame_id=conf["input_frame_id"],
                   max_abs=conf["max_abs_value"], future_tolerance_ns=int(conf["future_tolerance"] * 1e9),
                   log=log, table_path=table_path, mode=mode, cycles=cycles,
                   reorder_window_ns=int(round(conf["reorder_window_ms"] * 1e6)), check=check,
                   specs_text=conf.inputs.describe(), chi2_alpha=conf["consistency.chi2_alpha"],
                   control=conf.inputs.control, transforms=conf.transforms,
                   clock_tolerance_ns=int(round(conf["clock_tolerance_ms"] * 1e6)))
        pipe.publish_covariance = conf.publish_covariance
        pipe.screening.watch_only = conf["consistency.check"] == "auto" and conf.noise_max is None
        pipe.screening.options(conf["consistency.recertify"], conf["consistency.bias"], conf["consistency.reinit"])
        h_min = [min((cy.h[c] for cy in cycles), default=conf.robust[0] if conf.robust else 0.0) for c in range(sys_.N)]
        pipe.attribution.stamped.horizon = {c + 1: int(conf["switch_horizon"] * h * 1e9) for c, h in enumerate(h_min)}
        pipe.config = conf
        pipe.uncovered = tuple(conf.inputs.uncovered)
        for why in ([conf.inputs.uncovered_warning()] if pipe.uncovered else []) + ([] if check else [UNCHECKED]):
            log.warn(why)
        return pipe

    # ------------------------------------------------------------------ the parts' state
    @property
    def channel(self) -> int:
        """The latest channel received (arrival order; 0: none yet)."""
        return self.attribution.channel

    @property
    def window_ns(self) -> int:
        """The reorder window (``reorder_window_ms``), ns."""
        return self.attribution.window_ns

    @property
    def pending(self) -> dict[int, Pending]:
        """The samples waiting for their partners or their channel, by stamp."""
        return self.pairing.pending

    @property
    def check(self) -> bool:
        """Whether the consistency test is on (``consistency.check``, :mod:`~switchobs_ros.screening`)."""
        return self.screening.check

    @check.setter
    def check(self, on: bool) -> None:
        self.screening.check = bool(on)

    @property
    def chi2_alpha(self) -> float:
        """The chi-square gate's false-alarm rate (``consistency.chi2_alpha``; 0: no gate)."""
        return self.screening.chi2_alpha

    @chi2_alpha.setter
    def chi2_alpha(self, alpha: float) -> None:
        self.screening.chi2_alpha = alpha

    @property
    def late_channel(self) -> int:
        """Channel messages that arrived after samples they govern were answered."""
        return self.attribution.late

    @property
    def lost_channel(self) -> int:
        """Channel messages missing from the publisher's sequence."""
        return self.attribution.lost

    @property
    def input_topics(self) -> tuple[str, ...]:
        """Every input topic (sources, the channel topic, the control topic), relative names."""
        return tuple(s.topic for s in self.sources) + ((self.channel_topic,) if self.channel_topic else ()) \
            + ((self.control.topic,) if self.control else ())

    # ------------------------------------------------------------------ inputs
    def on_message(self, topic: str, msg: Any, now_ns: int, now_mono: float | None = None,
                   src_ns: int | None = None, seq: int | None = None) -> list[Estimate]:
        """A message on input ``topic`` (a source or the channel topic; relative name); ``seq``:
        the publisher's sequence number (:meth:`on_channel`, :meth:`on_input`)."""
        if topic == self.channel_topic:
            return self.on_channel(msg, src_ns=src_ns, now_mono=now_mono, seq=seq)
        if self.control is not None and topic == self.control.topic:
            self.on_control(msg, now_ns)
            return []
        return self.on_input(self.by_topic[topic].index, msg, now_ns, now_mono, src_ns, seq)

    def on_channel(self, msg: Any, src_ns: int | None = None, now_mono: float | None = None,
                   seq: int | None = None) -> list[Estimate]:
        """A channel-topic message (``std_msgs/UInt8``, or ``switchobs_msgs/ActiveChannel`` with its
        switching instant, attributed by stamps: :mod:`~switchobs_ros.switching`): validate, count,
        remember the channel (by its source timestamp ``src_ns`` when given, with the publisher's
        sequence number ``seq`` when known, :mod:`~switchobs_ros.attribution`); returns the pending
        samples it makes certain, answered."""
        out: list[Estimate] = []
        topic = self.channel_topic or CHANNEL_TOPIC
        try:
            c, rej = mb.read_channel(msg, self.N)
            if rej is not None:
                self.reject(topic, rej)
                self._withdraw_all(self.attribution.remember_invalid(src_ns, seq))
                return out
            self.accepted[topic] += 1
            if c != self.attribution.channel:
                if self.attribution.channel:
                    self.switches += 1
                self.attribution.switch(c, self.last_ns)
                self.dead_time.switched()
            if hasattr(msg, "header"):      # stamped: the switching instant (switchobs_ros.switching)
                self._withdraw_all(self.attribution.remember_switch(mb.stamp_to_ns(msg.header.stamp), c, src_ns, seq))
            elif src_ns is not None:
                self._withdraw_all(self.attribution.remember(int(src_ns), c, seq))
            if self.pairing.pending:        # (none waits: nothing to answer)
                self._advance(out, time.monotonic() if now_mono is None else now_mono)
        except Exception as err:
            self.internal_error(topic, err)
        return out

    def on_control(self, msg: Any, now_ns: int) -> bool:
        """A command on the control topic (:mod:`switchobs_ros.control`) received at node-clock
        ``now_ns``: checked, counted, and held from its stamp on; True when accepted."""
        c = self.control
        try:
            stamp_ns, u, rej = c.checked(msg, max_abs=self.max_abs, now_ns=now_ns, future_tolerance_ns=self.future_ns,
                                         obs_ns=self.obs_ns)
            if rej is not None:
                self.reject(c.topic, rej)
                if rej.reason == Reason.OLD_STAMP and c.changed_the_past(stamp_ns, u, self.obs_ns):
                    self.withdraw(f"a command for stamp {stamp_ns} arrived after samples it governs were answered: "
                                  "the estimates since then used another input than the plant's")
                return False
            self.accepted[c.topic] += 1
            c.accept(stamp_ns, u, self.observer, self.origin_ns)
            return True
        except Exception as err:
            self.internal_error(c.topic, err)
            return False

    def on_set_state(self, msg: Any, now_ns: int) -> bool:
        """A ``~/set_state`` message received at node-clock ``now_ns``
        (:func:`~switchobs_ros.set_state.apply_set_state`); True when applied."""
        return apply_set_state(self, msg, now_ns)

    def on_pose(self, part: str, msg: PoseStamped, now_ns: int, now_mono: float | None = None,
                src_ns: int | None = None) -> list[Estimate]:
        """A pose of the paper interface's ``part`` (``"camera"`` or ``"target"``); see :meth:`on_input`."""
        return self.on_input(self.by_topic[POSE_TOPICS[part]].index, msg, now_ns, now_mono, src_ns)

    def on_input(self, index: int, msg: Any, now_ns: int, now_mono: float | None = None,
                 src_ns: int | None = None, seq: int | None = None) -> list[Estimate]:
        """A message of source ``index`` received at node-clock ``now_ns`` (sent at ``src_ns`` on
        the publisher's clock, when known; ``seq``: its publication sequence number, whose gaps
        are counted as lost messages, :mod:`switchobs_ros.loss`).

        ``now_mono`` (default ``time.monotonic()``) starts the pairing timeout and the reorder
        window of a new pending sample. Returns the estimates produced (none while waiting).
        """
        src = self.sources[index]
        topic = src.topic
        out: list[Estimate] = []
        now_mono = time.monotonic() if now_mono is None else now_mono
        try:
            self.loss.seen(topic, seq)
            stamp_ns, values, rej = src.checked(msg, frame_id=self.in_frame, max_abs=self.max_abs,
                                                last_ns=self.last_ns[topic], now_ns=now_ns,
                                                future_tolerance_ns=self.future_ns, transforms=self.transforms)
            rej = self.attribution.refuse(src, stamp_ns, src_ns, rej)
            if rej is None and self.obs_ns is not None and stamp_ns <= self.obs_ns:
                rej = Rejection(Reason.OLD_STAMP, "header.stamp",
                                f"not newer than the estimate ({(self.obs_ns - stamp_ns) * 1e-9:.6f} s older)")
            if rej is not None:
                self.reject(topic, rej)
                return out
            self.accepted[topic] += 1
            skew = self.clocks.seen(topic, stamp_ns, now_ns)
            if skew:
                self.withdraw(skew)
            self.dead_time.accepted(src, stamp_ns, self.last_ns[topic])
            self.last_ns[topic] = stamp_ns
            self.last_accept_clock_ns = now_ns
            att = self.attribution
            pend = self.pairing.add(index, stamp_ns, values, src_ns, att.channel, now_mono, att.stamped.received)
            res = att.resolve(pend, now_mono)
            if (res.verdict is Verdict.CHANNEL and self.pairing.complete(pend, res.channel)) \
                    or (src.shared and len(pend.parts) == 1 and self.dead_time.certainly_blind(stamp_ns)):
                self.pairing.settle(pend.stamp_ns)       # older samples will not be completed now
            for s in self.pairing.overflow() if len(self.pairing.pending) > MAX_PENDING else ():   # partners overdue
                self._flush(s, out, now_mono)
            self._advance(out, now_mono)
        except Exception as err:
            self.internal_error(topic, err)
        return out

    # ------------------------------------------------------------------ answering samples
    def flush_overdue(self, now_mono: float, timeout: float) -> list[Estimate]:
        """Answer the pending samples whose reorder window has passed and that waited longer than
        ``timeout`` (s, monotonic clock) for their partners (the parts alone)."""
        out: list[Estimate] = []
        try:
            self._advance(out, now_mono, timeout=timeout)
        except Exception as err:
            self.internal_error("pairing", err)
        return out

    def flush_all(self) -> list[Estimate]:
        """Answer every pending sample now, in stamp order (end of a bag)."""
        out: list[Estimate] = []
        try:
            self._advance(out, math.inf, force=True)
        except Exception as err:
            self.internal_error("pairing", err)
        return out

    def _advance(self, out: list[Estimate], now_mono: float, *, timeout: float | None = None,
                 force: bool = False) -> None:
        """Answer the pending samples, oldest first, while each is ready: its channel certain and
        it due (:meth:`Pairing.due <switchobs_ros.pairing.Pairing.due>`), or ``force``."""
        while (pend := self.pairing.oldest()) is not None:
            res = self.attribution.resolve(pend, now_mono, force)
            if not res.certain:
                return
            if res.verdict is Verdict.CHANNEL and not (force or self.pairing.due(pend, res.channel, now_mono, timeout)):
                return
            self._flush(pend.stamp_ns, out, now_mono, res)

    def _flush(self, stamp_ns: int, out: list[Estimate], now_mono: float, res: Resolution | None = None) -> None:
        """Answer the pending sample at ``stamp_ns`` (every part, or those that came), with its
        channel ``res`` (None: resolved now, and not certain is :attr:`Verdict.UNCERTAIN`)."""
        pend = self.pairing.pop(stamp_ns)
        if pend is None:
            return
        if self.obs_ns is not None and stamp_ns <= self.obs_ns:     # overtaken (a set_state at a later stamp)
            self.dropped[Reason.OLD_STAMP.value] += len(pend.parts)
            return
        res = self._attribute(pend, now_mono, res)
        if res.verdict is not Verdict.CHANNEL:
            reason, detail = res.verdict.rejection
            self.reject_all([self.sources[i].topic for i in pend.parts],
                            Rejection(reason, self.channel_topic or "channel", detail))
            return
        self._answer(pend, res.channel, out)

    def _attribute(self, pend: Pending, now_mono: float, res: Resolution | None) -> Resolution:
        """The channel a sample is answered on. A sample sent while channel messages were lost,
        stamped within the clock tolerance of a switching instant, or whose channel was not proven
        within the reorder window, takes the one channel the consistency test allows, if exactly
        one; else its shared parts
        (the same rows in every channel) are used alone, on the observer's channel (no switching
        instant on an unknown channel), and its channel parts are rejected."""
        if res is None:
            res = self.attribution.resolve(pend, now_mono)
            if not res.certain:          # pushed out of the window before its channel was certain
                res = Resolution(Verdict.UNCERTAIN)
        if res.verdict not in (Verdict.LOST, Verdict.NEAR_SWITCH, Verdict.UNCERTAIN):
            return res
        if self.screening.names and self.origin_ns is not None:
            fits = self.screening.fitting_channels(pend, (pend.stamp_ns - self.origin_ns) * 1e-9)
            if len(fits) == 1:
                if res.verdict is Verdict.UNCERTAIN:
                    self.uncertain_named += 1
                else:
                    self.lost_channel_named += 1
                return Resolution.of(fits[0])
        if res.verdict is Verdict.NEAR_SWITCH:
            self.near_switch += 1
        elif res.verdict is Verdict.UNCERTAIN:
            self.uncertain += 1
        if not any(self.sources[i].shared for i in pend.parts):
            return res
        dropped = [i for i in pend.parts if not self.sources[i].shared]
        reason, detail = res.verdict.rejection
        self.reject_all([self.sources[i].topic for i in dropped],
                        Rejection(reason, self.channel_topic or "channel", detail))
        for i in dropped:
            pend.drop(i)
        return Resolution.of(self.observer.channel or self.attribution.channel)

    def _answer(self, pend: Pending, channel: int, out: list[Estimate]) -> None:
        """Test the sample read as ``channel`` and, if it passes, update the observer with it."""
        self.attribution.read_as(pend, channel)
        m = self.pairing.measurement(pend, channel)
        if self.origin_ns is None:
            self.origin_ns = pend.stamp_ns
            self.observer.reset(self.x0, 0.0)
            if self.control is not None:
                self.control.start(self.observer, self.origin_ns)
        t = (pend.stamp_ns - self.origin_ns) * 1e-9
        guessed = self.attribution.guessed(pend)
        if guessed and self.screening.names and len(self.screening.fitting_channels(pend, t)) == 1:
            guessed = False       # named by the consistency test (re-attributed below if not `channel`)
        m = self.screening.admit(pend, t, m)
        if m is None:
            return
        self.attribution.answered(pend, guessed)
        self._update(pend, t, m, out)

    def _update(self, pend: Pending, t: float, m: Measurement, out: list[Estimate]) -> None:
        """``SwitchedObserver.update`` with ``m`` at ``t``; append the estimate (withheld, and the
        estimator reset, when not finite)."""
        dt = t - self.observer.t
        if not self.bound_valid:    # none published until a re-certification or a reset restarts them
            self.observer.bounds_withdrawn = self.bound_invalid_why
        with np.errstate(all="ignore"):     # an overflow is caught below, not warned about
            violations = self.observer.residence_violations
            x_hat = self.observer.update(t, m.channel, m.y, rows=m.rows)
            if self.screening.taken(pend, t, m):    # re-certified from a window: the estimate may have
                x_hat = self.observer.x_hat         # restarted from its fit, publish that one with the bound
            self.obs_ns = pend.stamp_ns
            self.updates += 1
            self.parts_used += len(pend.parts)
            if m.partial:
                self.partial_updates += 1
            env_vals = self._envelope()
        if not np.isfinite(x_hat).all():
            # e.g. a gap so long that the exact step of an unstable system overflows: never
            # publish it; start again from the initial estimate at the next sample
            self.errors += 1
            self.nonfinite += 1
            self.log.error(f"non-finite estimate at stamp {pend.stamp_ns} (step of {dt:.6g} s): not published; "
                           "resetting the estimator")
            self.reset("non-finite estimate")
            return
        if not np.isfinite(env_vals[:None if self.bound_valid else self.N + 1]).all():
            # a bound that can no longer be computed: the estimate is good, the bounds are
            # withdrawn with the reason and it keeps answering (never a reset for it)
            self.withdraw(self.observer.bounds_withdrawn or f"the bounds are not finite at stamp {pend.stamp_ns}")
            env_vals[~np.isfinite(env_vals)] = NO_BOUND
        if self.observer.residence_violations != violations:     # the residence that ended at t
            self.log.warn(self.observer.residence_problem, throttle=True)
        if not self.bound_valid:
            env_vals[self.N + 1:] = NO_BOUND      # exact_bound (and noise_bound)
        P = self.observer.P if self.publish_covariance and self.covariance_due(len(out)) else None
        if P is not None and not np.isfinite(P).all():
            P = None
        out.append(Estimate(pend.stamp_ns, np.array(x_hat, dtype=float), env_vals, P, m.channel))

    def _envelope(self) -> np.ndarray:
        """``[z_1..z_N, paper_bound, exact_bound(, noise_bound)]`` now (nan where not computable)."""
        try:
            env = self.observer.envelope()
            return np.concatenate([env.z, [env.paper_bound, env.exact_bound]]
                                  + ([] if env.noise_bound is None else [[env.noise_bound]]))
        except (ArithmeticError, ValueError):       # e.g. the SVD of an overflowed Phi (LinAlgError)
            return np.full(self.N + 2 + (self.observer.noise_max is not None), np.nan)

    def _withdraw_all(self, reasons: list[str]) -> None:
        for why in reasons:
            self.withdraw(why)

    # ------------------------------------------------------------------ reset
    def reset(self, why: str) -> list[Estimate]:
        """Back to the initial estimate; the next accepted sample becomes the new time origin.

        The samples still waiting (for partners or for their channel) belong to what came before
        the reset: they are answered first, and returned. Then the pending samples and the
        per-topic stamp history are cleared (so a replay that starts over is accepted); the
        latest channel, the channel history and all counters are kept.
        """
        out: list[Estimate] = []
        if self.pending and self.origin_ns is not None:
            try:
                self._advance(out, math.inf, force=True)
            except Exception as err:
                self.internal_error("reset", err)
        self.dropped["reset"] += self.pairing.clear()
        self.origin_ns = None
        self.obs_ns = None
        self.last_ns = {s.topic: None for s in self.sources}
        self.attribution.reset()
        self.dead_time.switched()
        self.observer.reset(self.x0, 0.0)
        if self.control is not None:
            self.control.restart()
        self.resets += 1
        self.bound_valid = False
        self.bound_invalid_why = why
        self.log.info(f"estimator reset ({why}); exact_bound is {NO_BOUND:g} (no bound known) from now on")
        return out

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
        except (SwitchobsError, ArithmeticError, ValueError):   # ValueError: numpy's LinAlgError too
            return None
        if not np.isfinite(x).all():
            return None
        ok = self.bound_valid and math.isfinite(bound)      # a bound not computable there: none published
        return Prediction(int(stamp), x, float(bound) if ok else NO_BOUND, elapsed * 1e-9)

