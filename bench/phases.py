"""The estimator's CPU by phase: ``time.thread_time`` deltas accumulated per phase of the node's
spinning thread (not a test; used by ``bench/phase_node.py`` live and ``bench/bench_pipeline.py
--phases`` in process; bench/RESULTS.md).

:func:`install` wraps a fixed set of functions (the executor's wait, take and dispatch, the input
handler, the drain, the pipeline's steps, the screening, the observer's update, the envelope and
``P``, the demand checks, the writers, rclpy's ``publish``, the timers and the garbage collector's
passes) so that each call adds its *own* CPU time (its time minus that of the wrapped calls inside
it) to its phase. :func:`report` gives per phase the total, the calls and the time per answer, and
the thread's CPU that no phase saw (``other``). Each wrapped call costs two ``clock_gettime`` of the
thread's CPU clock (a system call, about 0.3-1 us each on this machine): :func:`calibrate` measures
it, and the report gives the overhead it adds per answer.
"""

from __future__ import annotations

import functools
import gc
import json
import time
from collections import defaultdict
from pathlib import Path
from typing import Any

__all__ = ["PHASES", "calibrate", "install", "report"]

_tt = time.thread_time_ns
_own: dict[str, int] = defaultdict(int)      # phase -> own ns
_calls: dict[str, int] = defaultdict(int)
_stack: list[int] = [0]                     # per open wrapped call: the ns its wrapped callees took
_state: dict[str, Any] = {"t0": None, "pipeline": None, "thread": None}


def _wrap(fn, phase: str):
    @functools.wraps(fn)
    def timed(*args, **kwargs):
        t0 = _tt()
        _stack.append(0)
        try:
            return fn(*args, **kwargs)
        finally:
            dt = _tt() - t0
            inner = _stack.pop()
            _own[phase] += dt - inner
            _calls[phase] += 1
            _stack[-1] += dt
    return timed


def _patch(owner: Any, name: str, phase: str) -> None:
    setattr(owner, name, _wrap(getattr(owner, name), phase))


def _patch_property(cls: type, name: str, phase: str) -> None:
    prop = cls.__dict__[name]
    setattr(cls, name, property(_wrap(prop.fget, phase), prop.fset, prop.fdel, prop.__doc__))


_gc_t0: list[int] = []


def _gc_callback(event: str, _info: dict) -> None:
    """A collection as a phase nested in whatever call triggered it."""
    if event == "start":
        _gc_t0.append(_tt())
        _stack.append(0)
    elif _gc_t0:
        dt = _tt() - _gc_t0.pop()
        _own["gc"] += dt - _stack.pop()
        _calls["gc"] += 1
        _stack[-1] += dt


#: (module, attribute path, phase): what :func:`install` wraps.
PHASES = (
    ("switchobs_ros.executor", "KeptWaitSetExecutor.spin_once", "executor: spin loop"),
    ("switchobs_ros.executor", "KeptWaitSetExecutor._wait", "executor: wait (wait set, rcl_wait, ready list)"),
    ("switchobs_ros.executor", "KeptWaitSetExecutor._serve", "executor: take + dispatch"),
    ("switchobs_ros.estimator", "EstimatorMixin._drain_inputs", "drain: takes + pairing timer arm"),
    ("switchobs_ros.estimator", "EstimatorMixin.pairing_callback", "timer: pairing"),
    ("switchobs_ros.estimator", "EstimatorMixin.diagnostics_callback", "timer: diagnostics"),
    ("switchobs_ros.estimator", "EstimatorMixin.diagnostics", "timer: diagnostics"),
    ("switchobs_ros.estimator", "EstimatorMixin._check_input_types", "timer: diagnostics (graph)"),
    ("switchobs_ros.demand", "Demand.covariance_wanted", "demand checks"),
    ("switchobs_ros.outputs", "listened", "demand checks"),
    ("switchobs_ros.outputs", "listened_each", "demand checks"),
    ("switchobs_ros.pipeline", "EstimatorPipeline.on_input", "pipeline: on_input (pairing, attribution, clocks)"),
    ("switchobs_ros.pipeline", "EstimatorPipeline.on_channel", "pipeline: on_channel"),
    ("switchobs_ros.pipeline", "EstimatorPipeline._advance", "pipeline: advance/flush/answer"),
    ("switchobs_ros.pipeline", "EstimatorPipeline._flush", "pipeline: advance/flush/answer"),
    ("switchobs_ros.pipeline", "EstimatorPipeline._answer", "pipeline: advance/flush/answer"),
    ("switchobs_ros.pipeline", "EstimatorPipeline._update", "pipeline: _update (checks, Estimate)"),
    ("switchobs_ros.pipeline", "EstimatorPipeline._envelope", "envelope"),
    ("switchobs_ros.sources", "Source.checked", "parse + checks"),
    ("switchobs_ros.screening", "Screening.admit", "screening"),
    ("switchobs_core.runtime.observer", "SwitchedObserver.update", "update"),
    ("switchobs_ros.outputs", "OutputsMixin._publish_all", "outputs: Python"),
    ("msg_bridge.raw", "RawLabelledArrayWriter.msg", "outputs: build (state, envelope, covariance)"),
    ("msg_bridge.raw", "RawLabelledArrayWriter.write", "outputs: build (state, envelope, covariance)"),
    ("msg_bridge.raw", "RawOdometryBatch.msgs", "outputs: build odometry"),
    ("msg_bridge.typed", "RawStateEstimateWriter.msg", "outputs: build typed"),
    ("msg_bridge.typed", "RawStateEstimateWriter.write", "outputs: build typed"),
    ("msg_bridge.typed", "ErrorBoundsWriter.msg", "outputs: build typed"),
    ("msg_bridge.markers", "RawMarkersWriter.msg", "outputs: build markers"),
)


def _publish_phase(pub: Any) -> str:
    """The phase of one rclpy ``publish``: by the output's topic."""
    name = pub.topic_name
    kind = "odometry" if name.endswith("/odom") else name.rsplit("/", 1)[-1]
    return f"outputs: rclpy publish {kind}"


def _wrap_publish(fn):
    phases: dict[int, str] = {}

    @functools.wraps(fn)
    def publish(self, msg):
        phase = phases.get(id(self))
        if phase is None:
            phase = phases[id(self)] = _publish_phase(self)
        t0 = _tt()
        _stack.append(0)
        try:
            return fn(self, msg)
        finally:
            dt = _tt() - t0
            _own[phase] += dt - _stack.pop()
            _calls[phase] += 1
            _stack[-1] += dt
    return publish


def _send_timed(send):
    """``outputs.send`` with its bytes timed as a publish; a message object goes on to
    ``Publisher.publish``, timed (and counted) there once."""
    timed = _wrap_publish(send)

    @functools.wraps(send)
    def send_timed(pub, data):
        return (timed if type(data) in (bytes, bytearray) else send)(pub, data)
    return send_timed


#: Finer phases inside the screening and the update (:func:`install` with ``fine=True``).
FINE = (
    ("switchobs_core.runtime.observer", "SwitchedObserver.prior", "screening: prior (x, rigorous sets at t)"),
    ("switchobs_core.runtime.consistency", "InnovationTest.check", "screening: innovation test"),
    ("switchobs_core.runtime.recovery", "Recovery.before", "screening: bias test"),
    ("switchobs_core.runtime.observer", "SwitchedObserver.prior_covariance", "screening: bias test's prior covariance"),
    ("switchobs_core.table.kalman", "KalmanPhase.P_block", "screening: table rows (P_block)"),
    # the core's per-sample Python around the rigorous set, its innovation test's block and the amortised read
    ("switchobs_core.numerics.rounding", "PendingSet.block", "screening: innovation test's block of the set"),
    ("switchobs_core.runtime.families.kalman", "KalmanTableGains._locked", "update: locked Kalman sample"),
    ("switchobs_core.runtime.observer", "SwitchedObserver.envelope", "envelope: observer"),
    ("switchobs_core.bounds.read", "AnchoredBound.read", "envelope: amortised read"),
    # the rigorous set's step through a Kalman sample's factored map (a tree without one of these skips it)
    ("switchobs_core.bounds.rigorous", "RoundingBound.propagated", "sets: propagated (prior's sets, own)"),
    ("switchobs_core.bounds.rigorous", "RoundingBound._noise", "sets: _noise (own)"),
    ("switchobs_core.bounds.rigorous", "RoundingBound.fused", "sets: fused (update's sets, own)"),
    ("switchobs_core.bounds.kalman_map", "SparseTransition.sandwich_either", "sets: Phi S Phi' (sandwich_either)"),
    ("switchobs_core.bounds.kalman_map", "KalmanMap.sandwich", "sets: factored Z, numpy (KalmanMap.sandwich)"),
    ("switchobs_core.bounds.kalman_map", "KalmanMap.step", "sets: factored step, kernel (KalmanMap.step)"),
    ("switchobs_core.numerics.rounding", "ErrorEllipsoid._plan", "sets: ErrorEllipsoid._plan"),
    ("switchobs_core.numerics.rounding", "ErrorEllipsoid._apply", "sets: ErrorEllipsoid._apply"),
    ("switchobs_core.numerics.rounding", "ErrorEllipsoid._block", "sets: ErrorEllipsoid._block (a prior's block)"),
)


def install(fine: bool = False) -> None:
    """Wrap :data:`PHASES` (``fine``: and :data:`FINE`), ``SwitchedObserver.P`` and the garbage
    collector; call before the node or pipeline is built (the input handler's closures are made at
    construction)."""
    import importlib

    for mod_name, path, phase in PHASES + (FINE if fine else ()):
        mod = importlib.import_module(mod_name)
        *owners, name = path.split(".")
        owner = mod
        for o in owners:
            owner = getattr(owner, o)
        if hasattr(owner, name):        # (a tree compared with --before may not have every function)
            _patch(owner, name, phase)
    from switchobs_core.runtime.observer import SwitchedObserver
    from switchobs_ros import estimator
    _patch_property(SwitchedObserver, "P", "covariance P")
    from rclpy.publisher import Publisher
    Publisher.publish = _wrap_publish(Publisher.publish)
    from switchobs_ros import outputs
    if hasattr(outputs, "send"):        # the outputs' own path to the publisher's handle
        outputs.send = _send_timed(outputs.send)
    _count_serves()
    orig = estimator.EstimatorMixin._input_handler

    def input_handler(self, index):
        _state["pipeline"] = self.pipeline
        return _wrap(orig(self, index), "handler (clocks, demand, loss)")
    estimator.EstimatorMixin._input_handler = input_handler
    gc.callbacks.append(_gc_callback)


def _entity_label(item: tuple) -> str:
    ent = item[1]
    topic = getattr(ent, "topic_name", None) or getattr(ent, "topic", None)
    if topic:
        return f"count: served {topic}"
    return f"count: served {type(ent).__name__}"


def _count_serves() -> None:
    """Counters without time (``count: ...``, calls per answer): each entity the executor serves,
    by topic or kind, and the waits by how many entities each found ready."""
    from switchobs_ros.executor import KeptWaitSetExecutor
    serve, wait = KeptWaitSetExecutor._serve, KeptWaitSetExecutor._wait

    def counted_serve(self, item):
        _calls[_entity_label(item)] += 1
        _own[_entity_label(item)] += 0
        return serve(self, item)

    def counted_wait(self, timeout_sec):
        before = len(self._ready)
        try:
            return wait(self, timeout_sec)
        finally:
            found = len(self._ready) - before
            k = f"count: waits that found {found if found < 3 else '3+'} ready"
            _calls[k] += 1
            _own[k] += 0
    KeptWaitSetExecutor._serve = counted_serve
    KeptWaitSetExecutor._wait = counted_wait


def start() -> None:
    """Zero every phase; the thread's CPU from now on is the report's total."""
    _own.clear()
    _calls.clear()
    _state["t0"] = _tt()


def calibrate(n: int = 20000) -> float:
    """The CPU one wrapped call adds (ns): a wrapped no-op against a bare one."""
    def nop():
        return None
    w = _wrap(nop, "_calibration")
    t0 = _tt()
    for _ in range(n):
        nop()
    bare = _tt() - t0
    t0 = _tt()
    for _ in range(n):
        w()
    wrapped = _tt() - t0
    _own.pop("_calibration", None)
    _calls.pop("_calibration", None)
    return (wrapped - bare) / n


def timed(fn, phase: str):
    """``fn`` wrapped into ``phase`` (a name starting ``bench:`` is the benchmark's own work: left
    out of the report and of its total)."""
    return _wrap(fn, phase)


def report(answers: int | None = None, path: str | Path | None = None) -> dict:
    """Per phase: own CPU (ms), calls and ms per answer; ``other``: the thread's CPU outside every
    phase since :func:`start`; written as JSON to ``path`` if given."""
    total = _tt() - (_state["t0"] or 0)
    if answers is None:
        pl = _state["pipeline"]
        answers = int(getattr(pl, "updates", 0)) if pl is not None else 0
    bench = sum(v for k, v in _own.items() if k.startswith("bench:"))     # the benchmark's own work
    total -= bench
    seen = sum(_own.values()) - bench
    phases = {k: {"ms": v * 1e-6, "calls": _calls[k]} for k, v in sorted(_own.items(), key=lambda kv: -kv[1])
              if not k.startswith("bench:")}
    phases["other (outside every phase)"] = {"ms": (total - seen) * 1e-6, "calls": 0}
    cost = calibrate()
    out = {"answers": answers, "thread_ms": total * 1e-6, "wrapper_ns": cost,
           "wrapper_ms_per_answer": cost * sum(_calls.values()) * 1e-6 / max(answers, 1), "phases": phases}
    if path is not None:
        Path(path).write_text(json.dumps(out, indent=1))
    return out


def table(rows: dict[str, dict]) -> str:
    """A markdown table of reports side by side (``{name: report}``), ms per answer."""
    names = list(rows)
    keys = list(dict.fromkeys(k for r in rows.values() for k in r["phases"]))
    lines = ["| phase | " + " | ".join(f"{n} (ms/answer, calls/answer)" for n in names) + " |",
             "|---|" + "---|" * len(names)]
    for k in keys:
        cells = []
        for n in names:
            r = rows[n]
            p = r["phases"].get(k)
            a = max(r["answers"], 1)
            cells.append("-" if p is None else f"{p['ms'] / a:.3f} ({p['calls'] / a:.1f})")
        lines.append(f"| {k} | " + " | ".join(cells) + " |")
    lines.append("| **thread total** | " + " | ".join(f"**{r['thread_ms'] / max(r['answers'], 1):.3f}**"
                                                     for r in rows.values()) + " |")
    lines.append("| (of it the wrappers' own cost) | " + " | ".join(f"{r['wrapper_ms_per_answer']:.3f}"
                                                                    for r in rows.values()) + " |")
    return "\n".join(lines)
