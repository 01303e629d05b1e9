"""``switchobs_bag estimate``: the estimator's pipeline over a bag, offline, deterministic.

The same :class:`switchobs_ros.pipeline.EstimatorPipeline` the estimator node runs, fed with the
bag's input messages (the system's input specification: by default ``/camera/active_channel``,
``/camera/pose`` and ``/target/pose``) in the recording's order, checked against their own stamps
(:mod:`switchobs_ros.bag.order`: log time, ties in the file's order; a target pose whose side of
a channel change the recording does not establish is rejected, ``ambiguous_channel``, and counted
in ``unordered``), with the node clock taken as each message's log time (what the node's clock
reads when ``switchobs_bag play`` replays the bag with ``/clock``). Halves of a camera/target
pair whose partner never comes are used alone when a newer pair completes or at the end of the
bag (the node's wall-clock pairing timeout has no offline meaning). So a live replay and the
offline run answer the same samples with the same estimates (tested to 1e-9).

Writes a new bag with the estimator's output topics (``<node>/state``, ``<node>/envelope``,
``<node>/<body>/odom``, the typed ``<node>/state_estimate`` and ``<node>/error_bounds``: the same
types and layouts the node publishes, decimated as the node decimates them (``output.*_every``:
every k-th estimate, 0 never; ``~/state`` always); log time = the log time of
the input that produced the estimate), the input bag's other topics copied (unless
``inputs=False``), and one ``/diagnostics`` message at the end in the node's shape (accepted and
rejected inputs). ``outputs`` selects among the outputs besides ``<node>/state`` (:data:`OUTPUTS`); a
selected one is written as when all are. Optionally a CSV: ``stamp_ns``, the state labels, the envelope
labels.

The bag is read as it is estimated (:meth:`switchobs_ros.bag.io.BagIn.log_order`, chunk by chunk)
and ordered in a window of log time (:mod:`switchobs_ros.bag.order_stream`: the order of
:func:`switchobs_ros.bag.order.order_messages` exactly, or, for a recording whose order needs more
than the window, a second run with the whole recording's order). The outputs are written as the
estimates come, so with ``keep=False`` (``switchobs_bag estimate``) memory does not grow with the
recording's length (the result then holds the counters and the number of estimates, not the
estimates: at n = 132 a covariance is 139 KB, 7 MB per second of a 50 Hz bag).
"""

from __future__ import annotations

import shutil
import time
from collections.abc import Collection
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from nav_msgs.msg import Odometry
from rclpy.serialization import serialize_message
from std_msgs.msg import Float64MultiArray
from switchobs_msgs.msg import ErrorBounds, StateEstimate

import msg_bridge as mb
from msg_bridge import Reason, Rejection
from msg_bridge.cdr_padding import zero_padding
from msg_bridge.raw import RawOdometryBatch
from msg_bridge.typed import ErrorBoundsWriter, StateEstimateWriter

from ..config import params_from_file
from ..pipeline import EstimatorPipeline
from .cdr import Template, header_stamp
from .io import CHANNEL_TYPES, BagError, BagIn, BagOut, channel_message, deserialize, type_name
from .order import Ordering, evidence, order_messages
from .order_stream import WINDOW_NS, BeyondWindow, StreamCounts, stream_order
from .typed_cdr import ErrorBoundsBytes

__all__ = ["OUTPUTS", "EstimateResult", "check_estimable", "estimate", "estimator_params", "nothing_estimated"]

#: The outputs besides ``<node>/state`` (always written) that :func:`estimate` can write, by the name of their
#: ``output.<name>_every`` decimation: ``envelope``, the bodies' ``odometry``, ``covariance`` (``<node>/covariance``)
#: and ``typed`` (``<node>/state_estimate`` and ``<node>/error_bounds``).
OUTPUTS = ("envelope", "odometry", "covariance", "typed")

#: The estimator's parameter values from params files (owned by switchobs_ros.config).
estimator_params = params_from_file



@dataclass
class EstimateResult:
    """What :func:`estimate` computed: the estimates in order (``keep``; else empty), the counters, the timing."""

    stamps: np.ndarray                 # (K,) int64 ns
    x_hat: np.ndarray                  # (K, n)
    envelope: np.ndarray               # (K, N + 2)
    state_labels: tuple
    P: np.ndarray | None = field(default=None, kw_only=True)   # (K, n, n) error covariances, if published
    envelope_labels: tuple
    messages_in: int                   # messages read from the bag
    inputs: int                        # estimator input messages among them
    accepted: dict = field(default_factory=dict)
    rejected: dict = field(default_factory=dict)
    updates: int = 0
    partial_updates: int = 0
    switches: int = 0
    inconsistent: int = 0              # samples the innovation test refused (switchobs_core.runtime.consistency)
    reattributed: int = 0              # samples it moved to the only channel that explains them
    bound_valid: bool = True           # False: the bounds were withdrawn (bound_invalid_why says why)
    bound_invalid_why: str = ""
    recertifications: int = 0          # bounds certified again from data (switchobs_core.runtime.recovery)
    recertified: str = ""              # the latest one: since when, from which window
    bias_alarms: int = 0               # the CUSUM bias test's alarms
    model_failures: int = 0            # channels the chi-square gate starved (a body off the model)
    seconds: float = 0.0               # wall time of the estimation loop (read to write)
    unanswered: dict = field(default_factory=dict)   # accepted samples without an estimate, by reason
    uncovered: tuple = ()              # channels that no source feeds (msg_bridge.InputSpecs.uncovered)
    uncovered_warning: str = ""        # the line that says so
    unordered: int = 0                 # parts whose side of a channel change the recording cannot tell (rejected)
    unproven_ties: int = 0             # log-time ties whose file order the stamps contradict
    whole_order: str = ""              # why the recording was ordered whole (the streamed order needed more)
    out: str | None = None
    csv: str | None = None
    count: int = 0                     # estimates made (those kept or not)


def estimate(bag_path: str | Path, cfg: dict, *, out: str | Path | None = None, csv: str | Path | None = None,
             storage: str | None = None, inputs: bool = True, node: str = "/estimator",
             progress: bool | None = False, keep: bool = True,
             outputs: Collection[str] | None = None, window_ns: int | None = WINDOW_NS) -> EstimateResult:
    """Run the estimator pipeline over the bag at ``bag_path`` (see the module docstring);
    ``progress``: a bar of the messages on stderr (None: on a terminal); ``keep``: the result holds
    every estimate (False: only their number; the bag and the CSV are written as they come);
    ``outputs``: the topics of :data:`OUTPUTS` written to the bag (None: all of them; ``<node>/state``
    always), each with the content and decimation it has when all are written (the others' topics
    are not in the bag); ``window_ns``: the recording is read and ordered as it goes, in this window
    of log time (:mod:`switchobs_ros.bag.order_stream`; None: read whole and ordered at once). When the
    order needs more than the window, the run starts again with the whole recording's order (what
    was written is removed first; ``whole_order`` says why): the result is the same either way."""
    if outputs is not None and set(outputs) - set(OUTPUTS):
        raise BagError(f"unknown output(s) {', '.join(sorted(set(outputs) - set(OUTPUTS)))} (known: "
                       f"{', '.join(OUTPUTS)})")
    args = dict(out=out, csv=csv, storage=storage, inputs=inputs, node=node, progress=progress, keep=keep,
                chosen=set(OUTPUTS if outputs is None else outputs))
    if window_ns is None:
        return _estimate(bag_path, cfg, window_ns=None, **args)
    try:
        return _estimate(bag_path, cfg, window_ns=window_ns, **args)
    except BeyondWindow as why:
        res = _estimate(bag_path, cfg, window_ns=None, **args)
        res.whole_order = str(why)
        return res


def _estimate(bag_path: str | Path, cfg: dict, *, out: str | Path | None, csv: str | Path | None,
              storage: str | None, inputs: bool, node: str, progress: bool | None, keep: bool,
              chosen: set[str], window_ns: int | None) -> EstimateResult:
    """:func:`estimate` with the outputs ``chosen``, streamed in ``window_ns`` (None: the whole recording's order)."""
    bag = BagIn(bag_path)
    try:
        pl = EstimatorPipeline.from_params(cfg)
        needed = {"/" + s.topic: s.type for s in pl.sources}     # the system's input specification
        if pl.channel_topic:
            needed["/" + pl.channel_topic] = CHANNEL_TYPES
        bag.require(needed, " (the estimator's inputs)")
        check_estimable(bag, pl)
        in_topics = dict(bag.topics)
        storage = storage or bag.storage or "mcap"
        total = bag.message_count
        if window_ns is None:
            msgs = bag.messages(order="file")     # ordered below (switchobs_ros.bag.order)
            bag.close()
    except BaseException:
        bag.close()
        raise
    sys_ = pl.system
    state_labels = tuple(sys_.state_labels)
    env_labels = mb.envelope_labels(sys_.N, noise_bound=pl.observer.noise_max is not None)
    bodies = mb.bodies(state_labels)
    frames = list(cfg["body_frames"]) or [b.name for b in bodies]
    if len(frames) != len(bodies):
        raise BagError(f"parameter 'body_frames' has {len(frames)} names for {len(bodies)} bodies")
    # outputs: the node's messages, serialised once and patched per estimate (cdr.Template)
    n, ne = len(state_labels), len(env_labels)
    w_state = Template(mb.labelled_array(np.zeros(n), state_labels, 0), array=("data",))
    w_env = Template(mb.labelled_array(np.zeros(ne), env_labels, 0), array=("data",))
    # the bodies' odometries in one buffer, covariance blocks from P: the node's writer (msg_bridge.raw)
    b_odom = RawOdometryBatch(bodies, cfg["world_frame"], frames)
    node = "/" + node.strip("/")
    t_state, t_env, t_cov = f"{node}/state", f"{node}/envelope", f"{node}/covariance"
    t_odom = [f"{node}/{b.name}/odom" for b in bodies]
    # the typed outputs (switchobs_msgs), as the node publishes them
    t_se, t_eb = f"{node}/state_estimate", f"{node}/error_bounds"
    # the typed estimate serialised once per shape (with P, without) and patched, as ~/state is
    t_se_tmpl = {has_P: Template(StateEstimateWriter(state_labels, cfg["world_frame"]).msg(
        np.zeros(n), 0, np.zeros((n, n)) if has_P else None), stamp=("header", "stamp"),
        arrays=[("x",), ("covariance",)] if has_P else [("x",)]) for has_P in (True, False)}
    w_eb = ErrorBoundsBytes(ErrorBoundsWriter(sys_.N, cfg["world_frame"], pl.observer.noise_max is not None))
    out_topics = {t_state, t_env, t_cov, t_se, t_eb, *t_odom}     # never copied from the input
    has_cov = pl.publish_covariance          # the estimates carry P
    bag_cov = has_cov and "covariance" in chosen and out is not None      # <node>/covariance in the bag
    # its template (17 424 labels at n = 132) made only for the bag that has the topic
    w_cov = Template(mb.labelled_array(np.zeros(n * n), mb.covariance_labels(state_labels), 0), array=("data",)) \
        if bag_cov else None

    writer = BagOut(out, storage) if out is not None else None
    table = CsvWriter(csv, state_labels, env_labels) if csv is not None else None
    try:
        if writer is not None:
            writer.add(t_state, type_name(Float64MultiArray))
            if "envelope" in chosen:
                writer.add(t_env, type_name(Float64MultiArray))
            if bag_cov:
                writer.add(t_cov, type_name(Float64MultiArray))
            if "odometry" in chosen:
                for t in t_odom:
                    writer.add(t, type_name(Odometry))
            if "typed" in chosen:
                writer.add(t_se, type_name(StateEstimate))
                writer.add(t_eb, type_name(ErrorBounds))
            writer.add("/diagnostics", type_name(DiagnosticArray))
            if inputs:
                for t, ty in in_topics.items():
                    if t not in out_topics and t != "/diagnostics":
                        writer.add(t, ty)
        count = 0
        stamps: list[int] = []
        xs: list[np.ndarray] = []
        envs: list[np.ndarray] = []
        covs: list[np.ndarray] = []
        # the node's output decimation (EstimatorNode._publish_all): the k-th estimate (from 0) goes out
        # on an output with output.<name>_every = m > 0 when k % m == 0; the result keeps every estimate
        every = {k: int(cfg.get(f"output.{k}_every", 1)) for k in OUTPUTS}

        def due(name: str, k: int) -> bool:
            return bool(every[name]) and k % every[name] == 0 and name in chosen

        def emit(ests, log_ns):
            nonlocal count
            for e in ests:
                k = count
                count += 1
                if keep:
                    stamps.append(e.stamp_ns)
                    xs.append(e.x_hat)
                    envs.append(e.envelope)
                    if has_cov:
                        covs.append(np.full((n, n), np.nan) if e.P is None else e.P)
                if table is not None:
                    table.row(e.stamp_ns, e.x_hat, e.envelope)
                sec, nsec = divmod(e.stamp_ns, mb.NS_PER_S)
                if writer is None:
                    continue
                topics, datas = [], []          # the estimate's messages, in this order, at one log time
                if bag_cov and e.P is not None and due("covariance", k):
                    topics.append(t_cov)
                    datas.append(w_cov.bytes(array=np.concatenate(((sec, nsec), e.P.ravel()))))
                topics.append(t_state)
                datas.append(w_state.bytes(array=[sec, nsec, *e.x_hat.tolist()]))
                if due("envelope", k):
                    topics.append(t_env)
                    datas.append(w_env.bytes(array=[sec, nsec, *e.envelope.tolist()]))
                if due("odometry", k):
                    topics += t_odom
                    datas += b_odom.msgs(e.x_hat, e.stamp_ns, e.P)
                if due("typed", k):
                    topics += (t_se, t_eb)
                    # with P: its doubles written from the array itself (the chunk copies them once)
                    datas.append(t_se_tmpl[False].bytes(e.stamp_ns, arrays=(e.x_hat,)) if e.P is None
                                 else t_se_tmpl[True].pieces(e.stamp_ns, arrays=(e.x_hat, e.P)))
                    datas.append(w_eb.bytes(e.envelope, e.stamp_ns, pl.bound_valid, pl.bound_invalid_why,
                                            pl.bound_note))
                writer.write_many(topics, log_ns, datas)

        sources = {"/" + s.topic: s for s in pl.sources}
        channel_topic = "/" + pl.channel_topic if pl.channel_topic else None
        # the commands u, if the bag has them (~/control is the node's private topic)
        ctl = pl.control
        ctl_topic = None if ctl is None else (f"{node}/{ctl.topic[2:]}" if ctl.topic.startswith("~/")
                                              else "/" + ctl.topic)

        def decoded(m, src):
            if src.raw:           # a fixed layout: its parsed form read from the bytes (msg_bridge.parse)
                p = src.parser.raw.parse(m.data)
                if p.__class__ is tuple:
                    return p
            return deserialize(m, mb.message_class(src.type))     # another encoding, or damaged: BagError

        n_inputs = 0
        n_msgs = 0
        last_ns = 0
        t0 = time.perf_counter()
        unordered_why = Rejection(Reason.AMBIGUOUS_CHANNEL, pl.channel_topic or "channel",
                                  "the recording does not establish whether it was sent before or after a change of "
                                  "the channel (log times that tie or contradict the stamps)")
        counts = StreamCounts()
        if window_ns is None:
            ordering = recording_order(msgs, pl, sources, channel_topic, ctl_topic)
            counts = StreamCounts(unordered=len(ordering.unordered), unproven=ordering.unproven)
            items = ((msgs[i], i in ordering.unordered) for i in ordering.order)
        else:
            kinds = _Kinds(pl, sources, channel_topic, ctl_topic)
            items = stream_order(((m.log_ns, m.topic, *kinds(m), m) for m in bag.log_order()), pl.future_ns, counts,
                                 window_ns)
        if progress is not False:       # a bar (None: on a terminal); tqdm is imported only for one
            from tqdm import tqdm
            items = tqdm(items, disable=None if progress is None else not progress, leave=False, unit="msg",
                         desc="estimate", total=total)
        for m, unord in items:
            n_msgs += 1
            last_ns = m.log_ns
            src = sources.get(m.topic)
            if src is not None:
                n_inputs += 1
                if unord:                           # never attributed by a guess: rejected, counted
                    pl.reject(src.topic, unordered_why)
                else:
                    emit(pl.on_input(src.index, decoded(m, src), m.log_ns, 0.0), m.log_ns)
            elif m.topic == channel_topic:
                n_inputs += 1
                emit(pl.on_channel(channel_message(m)), m.log_ns)
            elif m.topic == ctl_topic:
                n_inputs += 1
                pl.on_control(deserialize(m, mb.message_class(ctl.spec.type)), m.log_ns)
            if writer is not None and inputs and m.topic not in out_topics and m.topic != "/diagnostics":
                writer.write(m.topic, m.log_ns, m.data)
        emit(pl.flush_all(), last_ns)
        seconds = time.perf_counter() - t0
        if writer is not None:
            vals = [KeyValue(key=f"/{t} accepted", value=str(pl.accepted[t])) for t in pl.input_topics]
            vals += [KeyValue(key=f"rejected {t} {r}", value=str(n)) for (t, r), n in sorted(pl.rejected.items())]
            vals += [KeyValue(key="rejected total", value=str(sum(pl.rejected.values()))),
                     KeyValue(key="updates", value=str(pl.updates)),
                     KeyValue(key="partial updates", value=str(pl.partial_updates)),
                     KeyValue(key="switches", value=str(pl.switches)),
                     KeyValue(key="inconsistent samples", value=str(pl.inconsistent)),
                     KeyValue(key="re-attributed samples", value=str(pl.reattributed)),
                     KeyValue(key="unordered samples (recording)", value=str(counts.unordered)),
                     KeyValue(key="bounds valid", value=str(pl.bound_valid).lower()
                              + (f" ({pl.bound_note})" if pl.bound_note else "" if pl.bound_valid
                                 else f" ({pl.bound_invalid_why})")),
                     KeyValue(key="re-certifications", value=str(pl.recertifications)),
                     KeyValue(key="bias alarms", value=str(pl.bias_alarms)),
                     KeyValue(key="model failures (gate)", value=str(pl.model_failures))]
            arr = DiagnosticArray()
            arr.header.stamp = mb.ns_to_stamp(last_ns)
            arr.status = [DiagnosticStatus(level=DiagnosticStatus.OK, name=f"{node}: inputs (offline)",
                                           message="switchobs_bag estimate", hardware_id="switchobs", values=vals)]
            writer.write("/diagnostics", last_ns, bytes(zero_padding(arr, serialize_message(arr))))  # no heap bytes
    except BaseException as err:
        bag.close()
        if writer is not None:
            writer.close()
            if window_ns is not None and isinstance(err, (BeyondWindow, BagError)):
                shutil.rmtree(writer.path, ignore_errors=True)      # a part of a run that starts again or fails
        if table is not None:
            table.discard()
        raise
    bag.close()
    if writer is not None:
        writer.close()
    if table is not None:
        table.close()
    res = EstimateResult(
        stamps=np.array(stamps, dtype=np.int64), x_hat=np.array(xs).reshape(-1, n),
        envelope=np.array(envs).reshape(-1, len(env_labels)), state_labels=state_labels,
        P=np.array(covs).reshape(-1, n, n) if has_cov and keep else None,
        envelope_labels=env_labels, messages_in=n_msgs, inputs=n_inputs, accepted=dict(pl.accepted),
        rejected={f"{t} {r}": c for (t, r), c in pl.rejected.items()}, updates=pl.updates,
        partial_updates=pl.partial_updates, switches=pl.switches, inconsistent=pl.inconsistent,
        reattributed=pl.reattributed, bound_valid=pl.bound_valid, bound_invalid_why=pl.bound_invalid_why,
        recertifications=pl.recertifications, recertified=pl.recertified, bias_alarms=pl.bias_alarms,
        model_failures=pl.model_failures,
        seconds=seconds, out=str(out) if out is not None else None, unanswered=unanswered(pl),
        uncovered=tuple(pl.uncovered), uncovered_warning=pl.config.inputs.uncovered_warning(),
        unordered=counts.unordered, unproven_ties=counts.unproven, count=count,
        csv=str(csv) if csv is not None else None)
    return res


def recording_order(msgs: list, pl: EstimatorPipeline, sources: dict, channel_topic: str | None,
                    control_topic: str | None = None) -> Ordering:
    """The order to process the bag's messages (given in file order) and the unordered parts
    (:mod:`switchobs_ros.bag.order`), from their log times, file order, header stamps (the
    sources' and the commands') and the channel messages' values."""
    kinds = _Kinds(pl, sources, channel_topic, control_topic)
    stamp, dependent, channel, is_channel = (list(x) for x in zip(*map(kinds, msgs))) if msgs else ([], [], [], [])
    log_ns = [m.log_ns for m in msgs]
    ev = evidence([m.topic for m in msgs], log_ns, stamp, pl.future_ns)
    return order_messages(log_ns, stamp, ev, dependent, channel, is_channel)


class _Kinds:
    """Per message, what :func:`order_messages` takes of it: ``(stamp, dependent, channel, is_channel)``."""

    def __init__(self, pl: EstimatorPipeline, sources: dict, channel_topic: str | None, control_topic: str | None):
        self.pl, self.sources, self.channel_topic, self.control_topic = pl, sources, channel_topic, control_topic

    def __call__(self, m) -> tuple[int | None, bool, int | None, bool]:
        src = self.sources.get(m.topic)
        if src is not None:
            dependent = bool(self.channel_topic) and src.channel is None and not src.shared
            st = header_stamp(m.data) if src.type != mb.LABELLED_ARRAY else None
            if st is None:
                try:
                    st = divmod(src.read(deserialize(m, mb.message_class(src.type)))[0], mb.NS_PER_S)
                except (BagError, mb.BridgeError):
                    return None, dependent, None, False
            return mb.time_ns(*st), dependent, None, False
        if m.topic == self.channel_topic:
            c = mb.channel_value(channel_message(m))
            return None, False, (c if 1 <= c <= self.pl.N else None), True
        if m.topic == self.control_topic:       # a command: taken in stamp order in a tie the file does not prove
            st = header_stamp(m.data)
            ns = mb.time_ns(*st) if st is not None else None
            if ns is not None:
                return ns, False, None, False
        return None, False, None, False


def _listed(items: list[str]) -> str:
    return items[0] if len(items) == 1 else f"{', '.join(items[:-1])} and {items[-1]}"


def check_estimable(bag: BagIn, pl: EstimatorPipeline) -> None:
    """Refuse, before anything is written, a bag in which nothing can be estimated: every source
    topic empty, or the channel topic empty while every source needs the channel (a source of no
    fixed channel is attributed by it, :mod:`switchobs_ros.attribution`)."""
    topics = ["/" + s.topic for s in pl.sources]
    if not any(bag.counts.get(t, 0) for t in topics):
        raise BagError(f"bag {bag.path}: {'topics' if len(topics) > 1 else 'topic'} {_listed(topics)} "
                       f"{'hold' if len(topics) > 1 else 'holds'} no messages: nothing to estimate")
    ct = "/" + pl.channel_topic if pl.channel_topic else None
    if ct and not bag.counts.get(ct, 0) and all(s.channel is None for s in pl.sources):
        raise BagError(f"bag {bag.path}: channel topic {ct} holds no messages, and the samples of "
                       f"{', '.join(topics)} need their channel: nothing to estimate")


def nothing_estimated(res: EstimateResult) -> str:
    """Why a run produced no estimate (for the one-line refusal of ``switchobs_bag estimate``)."""
    if res.rejected and not any(res.accepted.values()):
        return "every input message was rejected (" + ", ".join(f"{k} {v}" for k, v in res.rejected.items()) + ")"
    if res.unanswered:
        return ("no valid measurement was answered (" + ", ".join(f"{k} {v}" for k, v in res.unanswered.items())
                + (f"; rejected: {', '.join(f'{k} {v}' for k, v in res.rejected.items())}" if res.rejected else "")
                + ")")
    return f"none of its {res.messages_in} messages is an input the estimator could use"


def unanswered(pl: EstimatorPipeline) -> dict[str, int]:
    """Accepted (valid) input messages that got no estimate, by named reason (only reasons > 0).

    The pipeline's own reasons (``inconsistent``: the consistency test refused the sample;
    ``no_channel``/``ambiguous_channel``: its channel was never certain; ``old_stamp``: overtaken;
    ``reset``: waiting when the estimator reset); ``non_finite_estimate``: the observer's update
    was not finite (withheld, the estimator reset); ``never_used``: accepted messages that no
    update consumed for another reason; ``internal_error``: exceptions caught while handling an
    input.
    """
    accepted = sum(pl.accepted.get(s.topic, 0) for s in pl.sources)
    dropped = dict(pl.dropped)
    out = {**dropped, "non_finite_estimate": pl.nonfinite,
           "never_used": max(0, accepted - pl.parts_used - sum(dropped.values())
                             - sum(len(p.parts) for p in pl.pending.values())),
           "internal_error": sum(c for (_, r), c in pl.rejected.items() if r == "internal_error")}
    return {k: int(v) for k, v in out.items() if v}


class CsvWriter:
    """``stamp_ns, <state labels>, <envelope labels>``, one row per estimate, full precision, written
    as the rows come (:meth:`close` when done; :meth:`discard` removes a run that failed)."""

    def __init__(self, path: str | Path, state_labels: tuple, envelope_labels: tuple) -> None:
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._f = self.path.open("w")
        self._f.write(",".join(("stamp_ns", *state_labels, *envelope_labels)) + "\n")

    def row(self, stamp_ns: int, x: np.ndarray, env: np.ndarray) -> None:
        # repr of each float, as ",".join(map(repr, ...)) writes them, formatted by the list's own repr; the
        # envelope's values repeat (the z of the channels at rest): each distinct one formatted once
        e = env.tolist()
        seen = set(e)
        if len(seen) + 4 < len(e) and 0.0 not in seen:      # 0.0 == -0.0: their reprs differ
            r = {v: repr(v) for v in seen}                  # a NaN is its own key (found by identity)
            tail = ",".join(map(r.__getitem__, e))
        else:
            tail = str(e)[1:-1].replace(", ", ",")
        head = str(x.tolist())[1:-1].replace(", ", ",")
        self._f.write(f"{int(stamp_ns)},{head}{',' if head and tail else ''}{tail}\n")

    def close(self) -> None:
        self._f.close()

    def discard(self) -> None:
        self._f.close()
        self.path.unlink(missing_ok=True)


def write_csv(path: str | Path, res: EstimateResult) -> None:
    """The CSV of :class:`CsvWriter` from a result that kept its estimates."""
    w = CsvWriter(path, res.state_labels, res.envelope_labels)
    for s, x, e in zip(res.stamps, res.x_hat, res.envelope):
        w.row(int(s), np.asarray(x, dtype=float), np.asarray(e, dtype=float))
    w.close()
