"""The estimator's input handling, without a node: validation, attribution, pairing, the
consistency test, the observer, counters.

:class:`EstimatorPipeline` is what the estimator node runs on every message, and what the bag
tools run over a bag without DDS (``switchobs_bag estimate``), so the live node and the
offline run compute the same estimates from the same messages. It holds no rclpy node,
executor or publisher: the caller passes each incoming message with the node clock (``now_ns``)
and, when the middleware gives it, the publisher's source timestamp (``src_ns``), and publishes
(or writes) the :class:`Estimate` objects it gets back.

Measurements
------------
The observer sees only measurements ``(stamp_ns, channel, rows, y)``
(:class:`switchobs_core.model.measurement.Measurement`). Where they come from is the system's input
specification (:mod:`msg_bridge.inputs`): sources (topic, message type, fields -> output rows),
each belonging to one channel or shared by all, and optionally a channel topic
(``std_msgs/UInt8``, 1..N) for sources shared by several channels. The paper's interface is
one such specification and the default: ``camera/pose`` (shared rows: the camera sees itself
whatever the channel), ``target/pose`` (the agent now in view: its channel comes from the
channel topic) and ``camera/active_channel``.

Pairing: the sources' messages with the same header stamp form one sample. The pipeline keeps
the pending samples by stamp (up to :data:`MAX_PENDING`) and runs the observer on a sample
when every source of its channel has arrived. A part whose partners do not come (a newer
sample completes, or the caller's :meth:`EstimatorPipeline.flush_overdue` finds it older than
``pairing_timeout``) is used alone through the observer's partial-rows input (``rows=``).

Attribution (never by arrival order)
------------------------------------
A source of one channel names its channel. A source shared by several channels takes the
channel that was active when its message was *sent*: the latest channel message whose source
timestamp (the publisher's clock, which rclpy passes in ``MessageInfo``) is not after the
sample's. DDS and the executor reorder messages of different topics under load, so a sample
waits, in a bounded reorder window (``reorder_window_ms``), until its channel is certain: a channel
message sent after it has arrived (the channel topic is reliable and keeps its order), or the
window has passed. A sample that is still ambiguous then (its source timestamp is older than
the channel history kept) is dropped and counted (``ambiguous_channel``), never guessed. A channel
message that arrives after samples it governs were answered (a window too short for the load)
withdraws the bounds: an answered sample may have had the wrong channel.

Lost channel messages: reliable keep-last delivery loses messages under load (a history that
overflows, a writer that no longer holds what the reader's transport dropped), so "a later
channel message has arrived" does not prove that none was sent in between. The publisher's
sequence number (rclpy's ``MessageInfo``, ``publication_sequence_number``) does: between two
received messages whose numbers are not consecutive the channel is unknown (measured beside
two busy loops: the first message of a new channel lost, a later one received, and the new
agent's poses were used as the old one's, errors of metres). A sample sent in such a gap has
its shared parts (the camera's own pose) used alone and its channel parts dropped and counted
(``ambiguous_channel``); with the consistency test on, a sample that only one channel's
reading passes is used whole on that channel (``lost_channel_named``). A gap found after
samples in it were answered on the window's expiry withdraws the bounds, unless the
consistency test had named their channel (the only reading it allowed). Without sequence
numbers (offline, or an rmw that has none) the history is taken as complete, as before. A
sequence that starts again (a restarted publisher: DDS numbers from 1) is not a gap; only a new
publisher's own first messages, if they are missing, are.

Without source timestamps (offline: a bag's messages are in the order the recorder wrote them)
the latest channel received is the channel, as the order is the publishing order.

Consistency (the model against the data)
----------------------------------------
With ``consistency.check`` ``always``, or ``auto`` (the default) when a noise bound
``noise.max`` is declared (0 for noise-free samples), every sample is tested before it is used
(:mod:`switchobs_core.runtime.consistency`): its innovation cannot exceed what the published bound
allows if the model holds. A sample that does proves the model broken for it: when exactly one
other channel explains it, it is re-attributed (``reattributed``); else it is rejected
(``inconsistent``), and every bound is withdrawn (:data:`NO_BOUND`) until a reset, with the
reason in diagnostics. A published guarantee is never silently false.

Dead time (``schedule.dead_time`` d > 0): after a switch the camera turns and only the shared
rows come. From the first shared-rows sample after a channel change (stamp ``s_0``) until the
first channel-specific part of the new channel, a shared-rows sample stamped before
``s_0 + d - (its period)`` is certainly blind (``s_0`` is at most one period after the switching
instant) and is used alone at once instead of waiting for a partner.

Time: observer time is ``(stamp - origin)`` in seconds, with ``origin`` the stamp of the first
sample accepted after start-up or a reset (integer nanoseconds until that subtraction).
Every estimate carries the stamp of the sample it answers.

Failure behaviour (the table is in docs/failures.md)
-------------------------------------------------------------------
* Every message is validated (:mod:`msg_bridge.validate`); a rejected one is counted under
  ``(topic, reason)`` and changes nothing else. Without source timestamps, a part of a channel
  topic sample stamped at or before the newest such part received before the latest channel
  change is ``stale_after_switch``: it was taken while the previous channel was active.
* Any exception while handling a message is caught, counted (``internal_error``) and logged;
  an estimate that is not finite is never returned (the estimator resets instead).
* Residence times are measured from the sample stamps at every switch and compared with
  what the gains were designed for (:meth:`EstimatorPipeline.residence`).
* Without samples, :meth:`EstimatorPipeline.predict` gives the observer's prediction at a
  later time and its exact bound ``||Phi(t, t0)|| e0``, which grows honestly with the outage.
"""

from __future__ import annotations

import bisect
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
from switchobs_core.exceptions import SwitchobsError
from switchobs_core.families import family_entry, family_of_table
from switchobs_core.model.measurement import Measurement
from switchobs_core.runtime.consistency import Consistency, check_innovation, chi2_gate, nis, spectral_norm
from switchobs_core.runtime.cycles import Residence
from switchobs_core.runtime.observer import SwitchedObserver

from .config import EstimatorConfig
from .core_config import load_or_design_table
from .params import ConfigError

__all__ = ["CHANNEL_TOPIC", "INPUT_TOPICS", "MAX_PENDING", "NO_BOUND", "POSE_TOPICS", "Estimate",
           "EstimatorPipeline", "PipelineLog", "Prediction", "Residence"]

#: ``exact_bound`` published after a reset: no bound is known any more. ``||Phi(t, t0)|| e0`` holds
#: only if ``||x_hat(t0) - x(t0)|| <= e0`` at the time origin; the configured ``e0`` is the user's
#: claim for the start, but after a reset (``~/reset``, a clock jump back, a non-finite estimate)
#: the plant has moved on and nothing bounds the new initial error. -1 is finite (the node never
#: publishes non-finite values) and cannot be a norm bound.
NO_BOUND = -1.0
#: The paper interface's topics (the default input specification; relative names).
POSE_TOPICS = {"camera": "camera/pose", "target": "target/pose"}
CHANNEL_TOPIC = "camera/active_channel"
#: The set-state input's name in the counters (robot_localization's set_pose analogue).
SET_STATE_TOPIC = "~/set_state"
INPUT_TOPICS = (POSE_TOPICS["camera"], POSE_TOPICS["target"], CHANNEL_TOPIC)
#: Samples kept waiting for their partners or for their channel (a backlog, the reorder window:
#: 300 ms at 1 kHz is 300 samples).
MAX_PENDING = 1024
#: Channel messages remembered for attribution by source timestamp.
CHANNEL_HISTORY = 256
#: :meth:`EstimatorPipeline._resolve`'s channel of a sample sent while channel messages were lost.
LOST_CHANNEL = -3


def _lost_between(a: int | None, b: int | None) -> int:
    """Channel messages lost between two received ones with publication sequence numbers ``a``
    then ``b`` (None: unknown, nothing is assumed lost). A number that does not increase is a
    new publisher (a camera restarted: DDS numbers a writer's messages from 1): only its own
    messages before ``b`` are missing, not the old one's after ``a``."""
    if a is None or b is None or b == a + 1:
        return 0
    return b - 1 if b <= a else b - a - 1


def _sequence(seq: Any) -> int | None:
    """A publisher's sequence number as rclpy reports it, None when unknown (absent, 0, or the
    rmw's 'unsupported' value, UINT64_MAX)."""
    if seq is None:
        return None
    seq = int(seq)
    return seq if 0 < seq < 2**63 else None


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


@dataclass(frozen=True)
class Source:
    """One input source as the pipeline uses it (built from a :class:`msg_bridge.InputSource`).

    ``rows[c - 1]`` are the rows of channel ``c``'s output that the source's fields feed;
    ``channel`` is None for a source shared by several channels; ``shared`` is True when its
    rows are the same quantities in every channel (the camera's own pose), so its samples need
    no channel to be read; ``read`` is the type's :class:`msg_bridge.FieldReader` ``read``;
    ``pose`` selects the PoseStamped checks of :func:`msg_bridge.check_pose`.
    """

    index: int
    topic: str
    type: str
    fields: tuple[str, ...]
    channel: int | None
    rows: tuple[tuple[int, ...], ...]
    shared: bool
    read: Any
    pose: bool


class _Part:
    """One source's message in a pending sample."""

    __slots__ = ("arrival_channel", "src_ns", "values")

    def __init__(self, values: np.ndarray, src_ns: int | None, arrival_channel: int):
        self.values = values
        self.src_ns = src_ns
        self.arrival_channel = arrival_channel


class _Pending:
    """One sample being assembled: the parts that have arrived for one stamp."""

    __slots__ = ("parts", "since", "stamp_ns")

    def __init__(self, stamp_ns: int, since: float):
        self.stamp_ns = stamp_ns
        self.parts: dict[int, _Part] = {}
        self.since = since


class EstimatorPipeline:
    """Validation, attribution, pairing, the consistency test and the switched observer for the
    estimator's inputs (module docstring).

    Build it with :meth:`from_params` (the estimator's parameter values). Feed it with
    :meth:`on_message` (any input topic), or :meth:`on_channel` / :meth:`on_input`; each returns
    the estimates it produced (possibly none), in stamp order.

    Counters (never cleared, reported in diagnostics): ``accepted`` (per input topic),
    ``rejected`` (per ``(topic, reason)``), ``updates``, ``partial_updates``, ``switches``,
    ``resets``, ``errors``, ``inconsistent``, ``reattributed``, ``late_channel``, ``lost_channel``,
    ``lost_channel_named``;
    ``last_rejection`` is the latest rejection's text.
    """

    def __init__(self, system, table, observer, *, x0: np.ndarray, sources: list[Source],
                 channel_topic: str | None = CHANNEL_TOPIC, input_frame_id: str = "map",
                 max_abs: float = 1.0e6, future_tolerance_ns: int = 500_000_000, log: PipelineLog | None = None,
                 table_path: Any = None, mode: str = "periodic", cycles: list | None = None,
                 reorder_window_ns: int = 50_000_000, check: bool = False, specs_text: str = "",
                 chi2_alpha: float = 0.0):
        self.system = system
        self.table = table
        self.table_path = table_path
        self.mode = mode
        self.cycles = list(cycles or [])
        self.observer = observer
        self.x0 = np.array(x0, dtype=float)
        self.sources = tuple(sources)
        self.by_topic = {s.topic: s for s in self.sources}
        self.channel_topic = channel_topic
        self.specs_text = specs_text
        self.in_frame = input_frame_id
        self.max_abs = max_abs
        self.future_ns = int(future_tolerance_ns)
        self.window_ns = int(reorder_window_ns)
        self.check = bool(check)
        self.chi2_alpha = float(chi2_alpha)
        self._gates: dict[int, float] = {}       # rows -> chi2.ppf(1 - alpha, rows)
        self.outliers = 0
        self.log = log or PipelineLog()
        self.N = system.N
        self._p = tuple(int(p) for p in system.p)
        self._C = tuple(np.asarray(C, dtype=float) for C in system.C)
        self._norms: dict = {}                   # (channel, rows) -> (C_rows, ||C_rows||_2 bound)
        # the sources every sample of channel c needs (its own and the shared ones)
        self._required = tuple(tuple(s.index for s in self.sources if s.channel in (None, c))
                               for c in range(1, self.N + 1))
        self._shared0 = next((s.index for s in self.sources if s.shared), None)
        # run-time state (cleared by reset)
        self.channel = 0                          # the latest channel received (arrival order)
        self.last_ns: dict[str, int | None] = {s.topic: None for s in self.sources}
        self.pending: dict[int, _Pending] = {}   # by stamp (ns)
        self.origin_ns: int | None = None
        self.obs_ns: int | None = None           # stamp of the last observer update
        self.last_accept_clock_ns: int | None = None
        self.switch_ns: int | None = None        # newest channel-topic part stamp before the latest change
        self.dead_ns = int(round(max((c.dead_time for c in self.cycles), default=0.0) * 1e9))
        self.blind_first_ns: int | None = None  # first shared-rows stamp after a channel change (dead time)
        self.target_since_switch = False
        self.cam_period_ns = 0                   # the latest gap between accepted shared-rows stamps
        self._upto = -1                          # newest stamp of a complete sample: older ones go alone
        self._ch_src: list[int] = []             # channel history by source timestamp (sorted)
        self._ch_val: list[int] = []
        self._ch_seq: list[int | None] = []      # publication sequence numbers (None: unknown)
        self._ch_dropped = False                 # history truncated (CHANNEL_HISTORY)
        self._answered_src = -1                  # newest source timestamp of an answered sample
        self._guessed_src = -1                   # the same, of one answered on the window's expiry
        self._last_fixed = 0                     # channel of the latest sample from a one-channel source
        # counters (never cleared)
        self.accepted: Counter = Counter()
        self.rejected: Counter = Counter()
        self.updates = 0
        self.partial_updates = 0
        self.switches = 0
        self.resets = 0
        self.states_set = 0
        self.inconsistent = 0
        self.reattributed = 0
        self.late_channel = 0
        self.lost_channel = 0       # channel messages missing from the publisher's sequence
        self.lost_channel_named = 0  # samples sent in such a gap whose channel the consistency test named
        self.last_inconsistency = ""
        self.parts_used = 0         # accepted messages an observer update consumed
        self.dropped: Counter = Counter()   # accepted messages no update used, by reason (never silent)
        self.bound_valid = True     # False after any reset, an inconsistent sample: see NO_BOUND
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
        # the table a family reads ('' = the table's own family, LMI when one is designed)
        design = family_entry(family).table if family else "lmi"
        table, table_path = load_or_design_table(
            conf["gain_table"], conf["gain_table_cache_dir"], sys_, mode, cycles, conf.robust, conf["delta"],
            log.info, family=design, rate=conf.rate, noise=conf.noise)
        if family and family_entry(family).stored and table.family != family:
            raise ConfigError(f"parameter 'gain_family' is '{family}' but the gain table holds {table.family} gains")
        try:
            # a family whose table brings its noise model takes none; the LMI covariance is tracked
            # only if published (the Kalman families always keep theirs)
            own_noise = family_entry(family or family_of_table(table)).rate
            observer = SwitchedObserver(sys_, table, mode=mode, cycles=cycles or None, x0=conf.x0, t0=0.0,
                                        e0=conf["e0"], bounds=conf.robust, family=family or None,
                                        noise=None if own_noise else conf.noise,
                                        track_covariance=conf.publish_covariance,
                                        noise_max=conf.noise_max)
        except SwitchobsError as err:
            raise ConfigError(f"observer: {err}") from None
        mode_check = conf["consistency.check"]
        check = mode_check == "always" or (mode_check == "auto" and conf.noise_max is not None)
        pipe = cls(sys_, table, observer, x0=conf.x0, sources=sources_from_specs(conf.inputs, sys_),
                   channel_topic=conf.inputs.channel_topic, input_frame_id=conf["input_frame_id"],
                   max_abs=conf["max_abs_value"], future_tolerance_ns=int(conf["future_tolerance"] * 1e9),
                   log=log, table_path=table_path, mode=mode, cycles=cycles,
                   reorder_window_ns=int(round(conf["reorder_window_ms"] * 1e6)), check=check,
                   specs_text=conf.inputs.describe(), chi2_alpha=conf["consistency.chi2_alpha"])
        pipe.publish_covariance = conf.publish_covariance
        pipe.config = conf
        return pipe

    # ------------------------------------------------------------------ inputs
    @property
    def input_topics(self) -> tuple[str, ...]:
        """Every input topic (sources, then the channel topic), relative names."""
        return tuple(s.topic for s in self.sources) + ((self.channel_topic,) if self.channel_topic else ())

    def on_message(self, topic: str, msg: Any, now_ns: int, now_mono: float | None = None,
                   src_ns: int | None = None, seq: int | None = None) -> list[Estimate]:
        """A message on input ``topic`` (a source or the channel topic; relative name); ``seq``:
        the publisher's sequence number of a channel message (:meth:`on_channel`)."""
        if topic == self.channel_topic:
            return self.on_channel(msg, src_ns=src_ns, now_mono=now_mono, seq=seq)
        return self.on_input(self.by_topic[topic].index, msg, now_ns, now_mono, src_ns)

    def on_channel(self, msg: UInt8, src_ns: int | None = None, now_mono: float | None = None,
                   seq: int | None = None) -> list[Estimate]:
        """A channel-topic message: validate, count, remember the channel (by its source timestamp
        ``src_ns`` when given, with the publisher's sequence number ``seq`` when known: a gap in
        the numbers is a lost message, module docstring); returns the pending samples it makes
        certain, answered."""
        out: list[Estimate] = []
        topic = self.channel_topic or CHANNEL_TOPIC
        try:
            rej = mb.check_channel(msg, self.N)
            if rej is not None:
                self.reject(topic, rej)
                k = bisect.bisect_right(self._ch_src, int(src_ns)) if src_ns is not None else 0
                if k and _sequence(seq) is not None:    # received, not lost: the channel is kept
                    self._remember_channel(int(src_ns), self._ch_val[k - 1], _sequence(seq))
                return out
            self.accepted[topic] += 1
            c = int(msg.data)
            if c != self.channel:
                if self.channel:
                    self.switches += 1
                self.channel = c
                # (no source timestamps) parts up to this stamp were taken while the previous
                # channel was active
                if self._dep_last_ns() is not None:
                    self.switch_ns = self._dep_last_ns()
                self.blind_first_ns = None
                self.target_since_switch = False
            if src_ns is not None:
                self._remember_channel(int(src_ns), c, _sequence(seq))
            self._advance(out, time.monotonic() if now_mono is None else now_mono)
        except Exception as err:
            self.internal_error(topic, err)
        return out

    def _remember_channel(self, src: int, c: int, seq: int | None = None) -> None:
        """Insert a channel message into the history by source timestamp; a late one that changes
        the channel of samples already answered, or a gap in the sequence numbers before one
        (lost messages) after samples in the gap were answered, withdraws the bounds (module
        docstring)."""
        k = bisect.bisect_right(self._ch_src, src)
        if src <= self._answered_src:
            before = self._ch_val[k - 1] if k else 0
            if before != c:
                self.late_channel += 1
                self._withdraw(f"a channel message (channel {c}) arrived after samples it governs were answered "
                               "(raise reorder_window_ms)")
        lost = _lost_between(self._ch_seq[k - 1], seq) if k else 0
        if lost:
            self.lost_channel += lost
            if self._guessed_src > self._ch_src[k - 1]:
                self._withdraw(f"channel messages were lost (publication sequence {self._ch_seq[k - 1]} then {seq}) "
                               "around samples already answered: their channel is not certain")
        self._ch_src.insert(k, src)
        self._ch_val.insert(k, c)
        self._ch_seq.insert(k, seq)
        if len(self._ch_src) > CHANNEL_HISTORY:
            del self._ch_src[0], self._ch_val[0], self._ch_seq[0]
            self._ch_dropped = True

    def _guessed(self, pend: _Pending) -> bool:
        """Whether the channel history does not prove the channel of a sample that depends on it:
        no channel message sent after it has arrived (answered on the window's expiry). A gap
        found later before such a sample withdraws the bounds (:meth:`_remember_channel`)."""
        srcs = self.sources
        if not self.channel_topic or not self._ch_src or all(srcs[i].shared for i in pend.parts) \
                or any(srcs[i].channel is not None for i in pend.parts):
            return False
        stamps = [p.src_ns for i, p in pend.parts.items() if not srcs[i].shared]
        return None not in stamps and self._ch_src[-1] <= max(stamps)

    def _gap_after(self, k: int) -> bool:
        """Whether channel messages were lost between history entries ``k`` and ``k + 1`` (their
        sequence numbers known and not consecutive)."""
        return _lost_between(self._ch_seq[k], self._ch_seq[k + 1]) > 0

    def _dep_last_ns(self) -> int | None:
        stamps = [self.last_ns[s.topic] for s in self.sources if s.channel is None and not s.shared
                  and self.last_ns[s.topic] is not None]
        return max(stamps) if stamps else None

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

    def on_pose(self, part: str, msg: PoseStamped, now_ns: int, now_mono: float | None = None,
                src_ns: int | None = None) -> list[Estimate]:
        """A pose of the paper interface's ``part`` (``"camera"`` or ``"target"``); see :meth:`on_input`."""
        return self.on_input(self.by_topic[POSE_TOPICS[part]].index, msg, now_ns, now_mono, src_ns)

    def on_input(self, index: int, msg: Any, now_ns: int, now_mono: float | None = None,
                 src_ns: int | None = None) -> list[Estimate]:
        """A message of source ``index`` received at node-clock ``now_ns`` (sent at ``src_ns`` on
        the publisher's clock, when known).

        ``now_mono`` (default ``time.monotonic()``) starts the pairing timeout and the reorder
        window of a new pending sample. Returns the estimates produced (none while waiting).
        """
        src = self.sources[index]
        topic = src.topic
        out: list[Estimate] = []
        now_mono = time.monotonic() if now_mono is None else now_mono
        try:
            stamp_ns, values, rej = self._validate(src, msg, now_ns)
            # no channel yet: rejected at once when arrival order decides (no source timestamp or no
            # window); else the sample waits: its channel message may still be in flight
            if rej is None and src.channel is None and self.channel_topic and not self.channel \
                    and (src_ns is None or not self.window_ns):
                rej = Rejection(Reason.NO_CHANNEL, self.channel_topic, "no active channel received yet")
            if not src.shared and src.channel is None and src_ns is None \
                    and (rej is None or rej.reason in (Reason.OLD_STAMP, Reason.DUPLICATE_STAMP)):
                rej = mb.check_after_switch(stamp_ns, self.switch_ns) or rej   # the more specific reason
            if rej is None and self.obs_ns is not None and stamp_ns <= self.obs_ns:
                rej = Rejection(Reason.OLD_STAMP, "header.stamp",
                                f"not newer than the estimate ({(self.obs_ns - stamp_ns) * 1e-9:.6f} s older)")
            if rej is not None:
                self.reject(topic, rej)
                return out
            self.accepted[topic] += 1
            if src.index == self._shared0 and self.last_ns[topic] is not None:
                self.cam_period_ns = stamp_ns - self.last_ns[topic]
            elif not src.shared:
                self.target_since_switch = True
            self.last_ns[topic] = stamp_ns
            self.last_accept_clock_ns = now_ns
            pend = self.pending.get(stamp_ns)
            if pend is None:
                pend = self.pending[stamp_ns] = _Pending(stamp_ns, now_mono)
            pend.parts[index] = _Part(values, None if src_ns is None else int(src_ns), self.channel)
            ch, _ = self._resolve(pend, now_mono)
            if self._complete(pend, ch) or (src.shared and len(pend.parts) == 1 and self._certainly_blind(stamp_ns)):
                self._upto = max(self._upto, stamp_ns)      # older samples will not be completed now
            while len(self.pending) > MAX_PENDING:          # the oldest one's partners are overdue
                self._flush(min(self.pending), out, now_mono, forced=True)
            self._advance(out, now_mono)
        except Exception as err:
            self.internal_error(topic, err)
        return out

    def _validate(self, src: Source, msg: Any, now_ns: int) -> tuple[int, np.ndarray, Rejection | None]:
        """The message's stamp and values, and why it is rejected (None: valid)."""
        last = self.last_ns[src.topic]
        if src.pose:      # every field of a pose checked, as before input specifications
            rej = mb.check_pose(msg, frame_id=self.in_frame, max_abs=self.max_abs, last_ns=last, now_ns=now_ns,
                                future_tolerance_ns=self.future_ns)
            if rej is not None and rej.reason is Reason.BAD_STAMP:
                return 0, np.empty(0), rej
            stamp_ns, _, values = src.read(msg)
            return stamp_ns, values, rej
        try:
            stamp_ns, frame, values = src.read(msg)
        except mb.BridgeError as err:       # a bad stamp, or a labelled array of another layout
            return 0, np.empty(0), err.rejection or Rejection(Reason.BAD_LAYOUT, "layout", str(err))
        values = np.asarray(values, dtype=float)
        rej = mb.check_values(values, src.fields, max_abs=self.max_abs)
        if rej is None and self.in_frame and src.type != mb.LABELLED_ARRAY and frame != self.in_frame:
            rej = Rejection(Reason.WRONG_FRAME, "header.frame_id", f"'{frame}' (expected '{self.in_frame}')")
        if rej is None:
            rej = mb.check_stamp(stamp_ns, last_ns=last, now_ns=now_ns, future_tolerance_ns=self.future_ns)
        return stamp_ns, values, rej

    # ------------------------------------------------------------------ attribution and pairing
    def _resolve(self, pend: _Pending, now_mono: float, force: bool = False) -> tuple[int, bool]:
        """The channel of a pending sample and whether it is certain (module docstring).

        Channel 0: none was active when the sample was sent; -1: two one-channel sources disagree;
        -2: ambiguous (older than the channel history kept); :data:`LOST_CHANNEL`: sent while
        channel messages were lost (a gap in their sequence numbers).
        """
        srcs = self.sources
        fixed = {srcs[i].channel for i in pend.parts if srcs[i].channel is not None}
        if fixed:
            return (fixed.pop(), True) if len(fixed) == 1 else (-1, True)
        dep = [p for i, p in pend.parts.items() if not srcs[i].shared] or list(pend.parts.values())
        if not self.channel_topic:          # shared rows only, one-channel sources elsewhere
            return self._last_fixed, True
        stamps = [p.src_ns for p in dep]
        if any(s is None for s in stamps) or not self._ch_src:
            if self._ch_src or not self.window_ns or any(s is None for s in stamps) or force:
                return dep[0].arrival_channel if dep[0].arrival_channel else self.channel, True
            # source timestamps but no channel message yet: wait for one (the window)
            return 0, now_mono - pend.since >= self.window_ns * 1e-9
        s = max(stamps)
        k = bisect.bisect_right(self._ch_src, s) - 1
        certain = force or self._ch_src[-1] > s or now_mono - pend.since >= self.window_ns * 1e-9
        if k < 0:
            return (-2 if self._ch_dropped else 0), certain
        if k + 1 < len(self._ch_src) and self._gap_after(k):
            return LOST_CHANNEL, True
        return self._ch_val[k], certain

    def _complete(self, pend: _Pending, ch: int) -> bool:
        return ch > 0 and all(i in pend.parts for i in self._required[ch - 1])

    def _advance(self, out: list[Estimate], now_mono: float, *, timeout: float | None = None,
                 force: bool = False) -> None:
        """Answer the pending samples, oldest first, while each is ready: its channel certain and
        it complete, superseded by a newer complete one, overdue (``timeout``) or ``force``."""
        while self.pending:
            s = min(self.pending)
            pend = self.pending[s]
            ch, certain = self._resolve(pend, now_mono, force)
            if not certain:
                return
            if not (ch <= 0 or force or s <= self._upto or self._complete(pend, ch)
                    or (timeout is not None and now_mono - pend.since > timeout)):
                return
            self._flush(s, out, now_mono, channel=ch)

    def _certainly_blind(self, stamp_ns: int) -> bool:
        """Whether a shared-rows sample at ``stamp_ns`` lies in the dead time for sure (module docstring)."""
        if not self.dead_ns or self.target_since_switch:
            return False
        if self.blind_first_ns is None:
            self.blind_first_ns = stamp_ns
        return stamp_ns - self.blind_first_ns < self.dead_ns - self.cam_period_ns

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

    def _sample(self, pend: _Pending, ch: int) -> Measurement:
        """The measurement of a pending sample read as channel ``ch`` (rows None: all of them)."""
        rows: list[int] = []
        vals: list[float] = []
        for i, part in pend.parts.items():
            rows.extend(self.sources[i].rows[ch - 1])
            vals.extend(part.values.tolist())
        order = sorted(range(len(rows)), key=rows.__getitem__)
        r = tuple(rows[k] for k in order)
        y = np.array([vals[k] for k in order], dtype=float)
        return Measurement(pend.stamp_ns, ch, None if r == tuple(range(self._p[ch - 1])) else r, y)

    def _flush(self, stamp_ns: int, out: list[Estimate], now_mono: float, *, channel: int | None = None,
               forced: bool = False) -> None:
        """Run the observer on a pending sample (every part, or those that came); append the estimate."""
        pend = self.pending.pop(stamp_ns, None)
        if pend is None:
            return
        if self.obs_ns is not None and stamp_ns <= self.obs_ns:     # overtaken (a set_state at a later stamp)
            self.dropped[Reason.OLD_STAMP.value] += len(pend.parts)
            return
        if channel is None:
            channel, certain = self._resolve(pend, now_mono)
            if not certain:          # pushed out of the window before its channel was certain
                channel = -2
        lost = "sent while channel messages were lost (a gap in the publisher's sequence numbers)"
        if channel == LOST_CHANNEL and self.check and self.bound_valid and self.origin_ns is not None:
            # the consistency test names the channel when it allows exactly one (the model holds)
            fits = self._fitting_channels(pend, (pend.stamp_ns - self.origin_ns) * 1e-9)
            if len(fits) == 1:
                channel = fits[0]
                self.lost_channel_named += 1
        if channel == LOST_CHANNEL and any(self.sources[i].shared for i in pend.parts):
            # its channel is unknown: the shared parts (the same rows in every channel) alone, on
            # the observer's channel (no switching instant on an unknown channel); the rest dropped
            for i in [i for i in pend.parts if not self.sources[i].shared]:
                self.reject(self.sources[i].topic,
                            Rejection(Reason.AMBIGUOUS_CHANNEL, self.channel_topic or "channel", lost))
                self.dropped[Reason.AMBIGUOUS_CHANNEL.value] += 1
                del pend.parts[i]
            channel = self.observer.channel or self.channel
        topics = [self.sources[i].topic for i in pend.parts]
        if channel <= 0:
            reason, detail = {
                0: (Reason.NO_CHANNEL, "no active channel when it was sent"),
                -1: (Reason.AMBIGUOUS_CHANNEL, "parts from sources of different channels share one stamp"),
                -2: (Reason.AMBIGUOUS_CHANNEL, "its channel was not certain within the reorder window"),
                LOST_CHANNEL: (Reason.AMBIGUOUS_CHANNEL, lost),
            }[channel]
            for t in topics:
                self.reject(t, Rejection(reason, self.channel_topic or "channel", detail))
            self.dropped[reason.value] += len(pend.parts)
            return
        if self.sources[next(iter(pend.parts))].channel is not None:
            self._last_fixed = channel
        m = self._sample(pend, channel)
        if self.origin_ns is None:
            self.origin_ns = pend.stamp_ns
            self.observer.reset(self.x0, 0.0)
        t = (pend.stamp_ns - self.origin_ns) * 1e-9
        dt = t - self.observer.t
        srcs = [p.src_ns for p in pend.parts.values() if p.src_ns is not None]
        guess = self._guessed(pend)
        if guess and self.check and self.bound_valid and len(self._fitting_channels(pend, t)) == 1:
            guess = False       # named by the consistency test (re-attributed below if not `channel`)
        if self.check and self.bound_valid:
            m = self._consistent(pend, t, m)
            if m is None:
                self.dropped[Reason.INCONSISTENT.value] += len(pend.parts)
                return
        elif self.chi2_alpha > 0 and not self._gate(pend, t, m):
            self.dropped[Reason.OUTLIER.value] += len(pend.parts)
            return
        if srcs:
            self._answered_src = max(self._answered_src, max(srcs))
            if guess:
                self._guessed_src = max(self._guessed_src, max(srcs))
        with np.errstate(all="ignore"):     # an overflow is caught below, not warned about
            violations = self.observer.residence_violations
            x_hat = self.observer.update(t, m.channel, m.y, rows=m.rows)
            self.obs_ns = pend.stamp_ns
            self.updates += 1
            self.parts_used += len(pend.parts)
            if m.partial:
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
        out.append(Estimate(pend.stamp_ns, np.array(x_hat, dtype=float), env_vals, P, m.channel))

    # ------------------------------------------------------------------ consistency
    def _consistent(self, pend: _Pending, t: float, m: Measurement) -> Measurement | None:
        """The innovation test of :mod:`switchobs_core.runtime.consistency` before the sample is used.

        Returns the measurement to use (re-attributed when exactly one other channel explains
        the sample), or None when the sample is rejected (the bounds are then withdrawn)."""
        with np.errstate(all="ignore"):
            prior = self.observer.prior(t)

        def test(mc: Measurement) -> Consistency:
            return self._innovation(mc, prior)

        first = test(m)
        if first.ok:
            return m
        # re-attribution: only a sample whose channel came from the channel topic can have another
        if any(self.sources[i].channel is None and not self.sources[i].shared for i in pend.parts):
            fits = [mc for mc in (self._sample(pend, c) for c in range(1, self.N + 1) if c != m.channel)
                    if test(mc).ok]
            if len(fits) == 1:
                self.reattributed += 1
                self.log.warn(f"sample at stamp {pend.stamp_ns} re-attributed from channel {m.channel} to "
                              f"{fits[0].channel}, the only channel consistent with it ({first.describe()})",
                              throttle=True)
                return fits[0]
        self.inconsistent += 1
        self.last_inconsistency = f"stamp {pend.stamp_ns}: {first.describe()}"
        topic = next((self.sources[i].topic for i in pend.parts if not self.sources[i].shared),
                     self.sources[next(iter(pend.parts))].topic)
        self.reject(topic, Rejection(Reason.INCONSISTENT, "innovation", first.describe()))
        self._withdraw(f"inconsistent sample at stamp {pend.stamp_ns} ({first.describe()}): the model does not "
                       "hold for the data (wrong channel or frame, a faulty sensor, a body off the model, or noise "
                       "beyond noise.max)")
        return None

    def _innovation(self, mc: Measurement, prior: tuple) -> Consistency:
        """The innovation test of ``mc`` against the observer's ``prior`` (``(x_hat, exact, noise)``
        of :meth:`~switchobs_core.runtime.observer.SwitchedObserver.prior` at its time)."""
        x_p, exact, noisy = prior
        vmax = self.observer.noise_max
        key = (mc.channel, mc.rows)
        if key not in self._norms:
            C = self._C[mc.channel - 1]
            C = C if mc.rows is None else C[list(mc.rows)]
            self._norms[key] = (C, spectral_norm(C))
        C, nC = self._norms[key]
        b = exact if vmax is None else noisy
        return check_innovation(C, mc.channel, b, 0.0 if vmax is None else vmax[mc.channel - 1], x_p, mc.y, nC)

    def _fitting_channels(self, pend: _Pending, t: float) -> list[int]:
        """The channels whose reading of the pending sample passes the innovation test at ``t``."""
        with np.errstate(all="ignore"):
            prior = self.observer.prior(t)
        return [c for c in range(1, self.N + 1) if self._innovation(self._sample(pend, c), prior).ok]

    def _gate(self, pend: _Pending, t: float, m: Measurement) -> bool:
        """The chi-square gate (``consistency.chi2_alpha``): False, counted and rejected, when the
        sample's normalised innovation exceeds the gate (a false alarm with probability alpha
        when the noise model holds). No bound is involved: none is claimed under such noise."""
        obs = self.observer
        with np.errstate(all="ignore"):
            P = obs.prior_covariance(t)
            if P is None or obs.noise is None:
                return True
            x_p = obs.predict(t, hold=True)
        C = self._C[m.channel - 1] if m.rows is None else self._C[m.channel - 1][list(m.rows)]
        p = C.shape[0]
        if p not in self._gates:
            self._gates[p] = chi2_gate(p, self.chi2_alpha)
        v = nis(C, P, obs.noise.R(m.channel, m.rows), x_p, m.y)
        if v <= self._gates[p]:
            return True
        self.outliers += 1
        topic = next((self.sources[i].topic for i in pend.parts if not self.sources[i].shared),
                     self.sources[next(iter(pend.parts))].topic)
        self.reject(topic, Rejection(Reason.OUTLIER, "innovation",
                                     f"NIS {v:.3g} > {self._gates[p]:.3g} (chi-square, {p} rows, alpha "
                                     f"{self.chi2_alpha:g})"))
        return False

    def _withdraw(self, why: str) -> None:
        """No bound can be guaranteed any more: publish :data:`NO_BOUND` until a reset."""
        if self.bound_valid:
            self.log.error(f"bounds withdrawn: {why}")
        self.bound_valid = False
        self.bound_invalid_why = why

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

    def reset(self, why: str) -> list[Estimate]:
        """Back to the initial estimate; the next accepted sample becomes the new time origin.

        The samples still waiting (for partners or for their channel) belong to what came before
        the reset: they are answered first, and returned. Then the pending samples and the
        per-topic stamp history are cleared (so a replay that starts over is accepted); the
        active channel and all counters are kept.
        """
        out: list[Estimate] = []
        if self.pending and self.origin_ns is not None:
            try:
                self._advance(out, math.inf, force=True)
            except Exception as err:
                self.internal_error("reset", err)
        self.dropped["reset"] += sum(len(p.parts) for p in self.pending.values())
        self.pending = {}
        self.origin_ns = None
        self.obs_ns = None
        self._upto = -1
        self.last_ns = {s.topic: None for s in self.sources}
        self.switch_ns = None
        self.blind_first_ns = None
        self.target_since_switch = False
        self.observer.reset(self.x0, 0.0)
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
        except (SwitchobsError, ArithmeticError, ValueError, np.linalg.LinAlgError):
            return None
        if not (np.isfinite(x).all() and math.isfinite(bound)):
            return None
        return Prediction(int(stamp), x, float(bound) if self.bound_valid else NO_BOUND, elapsed * 1e-9)


_POSE_TYPE = "geometry_msgs/msg/PoseStamped"


def sources_from_specs(specs: Any, system: Any) -> list[Source]:
    """The pipeline's sources of an input specification (:class:`msg_bridge.InputSpecs`).

    A source is *shared* when it serves every channel and feeds the same rows of ``C`` in each
    (the camera's own pose; :class:`msg_bridge.InputSource`): its samples need no channel to be read.
    """
    out = []
    for k, spec in enumerate(specs.sources):
        rows = tuple(tuple(spec.rows_for(c)) for c in range(1, system.N + 1))
        out.append(Source(k, spec.topic, spec.type, tuple(spec.fields), spec.channel, rows, bool(spec.shared),
                          spec.reader.read, spec.type == _POSE_TYPE))
    return out


def channel_bodies(system: Any, bodies: Any) -> dict[int, str]:
    """The body each channel sees (the one whose outputs belong to that channel alone, as
    ``agent2`` for channel 2 of the camera scenarios): ``{channel: body name}``, channels whose
    outputs name no such body left out (the markers then highlight none)."""
    names = {b.name for b in bodies}
    common = set.intersection(*(set(o) for o in system.output_labels)) if system.N else set()
    out = {}
    for c, labels in enumerate(system.output_labels, start=1):
        own = {lab.rpartition(".")[0] for lab in labels if lab not in common} & names
        if len(own) == 1:
            out[c] = own.pop()
    return out
