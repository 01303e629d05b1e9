"""The estimator's ``/diagnostics``: what the node reports, built outside the node.

Three statuses, in the shape of ROS's diagnostic_updater (not among the PyPI wheels): the
configuration (static: system, table, schedule, gain family, noise model, designs), the observer
(dynamic: channel, cycle, gains, bounds, residence times against the design, sensor outage) and
the inputs (rates over the last period on the node clock, accepted and rejected counts by
reason). :class:`EstimatorDiagnostics` reads the pipeline and its observer; the node passes what
only it knows (clock jumps, outage predictions) as a :class:`NodeState`.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue

from switchobs_core.numerics.norms import gain_norms

__all__ = ["EstimatorDiagnostics", "FREQUENCY_TOLERANCE", "NodeState", "kv"]

#: Measured rates outside ``[lo, hi]`` times the expected one turn the inputs status WARN (the
#: diagnostic_updater FrequencyStatus default tolerance, 10 %).
FREQUENCY_TOLERANCE = (0.9, 1.1)

def _fmt(v) -> str:
    if isinstance(v, bool):
        return str(v).lower()
    if isinstance(v, float):
        return f"{v:.6g}"
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_fmt(x) for x in v) + "]"
    return str(v)


def kv(k: Any, v: Any) -> KeyValue:
    """One diagnostic value: strings as they are, numbers with 6 significant digits, lists bracketed."""
    return KeyValue(key=str(k), value=v if isinstance(v, str) else _fmt(v))


@dataclass
class NodeState:
    """What the node knows beyond the pipeline: clock jumps, the sensor timeout, outage predictions."""

    clock_jumps_back: int
    clock_jumps_forward: int
    last_clock_jump: str
    sensor_timeout: float
    last_prediction: Any
    predictions: int
    ignored_inactive: int = 0
    published: dict | None = None       # messages published per output (switchobs_ros.demand)


class EstimatorDiagnostics:
    """Builds the estimator's DiagnosticArray (module docstring); keeps the input-rate baseline."""

    def __init__(self, name: str, pipeline: Any, now_ns: int):
        self.name = name
        self.pipeline = pipeline
        self._t_first_ns = now_ns
        self._rate_base = (now_ns, Counter(), 0, 0, 0)

    def array(self, now, node: NodeState) -> DiagnosticArray:
        """The /diagnostics message at node-clock time ``now`` (an rclpy Time)."""
        now_ns = now.nanoseconds
        conf = self._configuration()
        ob = self._observer(node) + self._bounds() + self._model_against_data()
        level, msg = self._observer_status(now_ns, node, ob)
        inp, new_rej, new_lost, freq_problem = self._inputs(now_ns)
        arr = DiagnosticArray()
        arr.header.stamp = now.to_msg()
        name = self.name
        arr.status = [
            DiagnosticStatus(level=DiagnosticStatus.OK, name=f"{name}: configuration", message="loaded",
                             hardware_id="switchobs", values=conf),
            DiagnosticStatus(level=level, name=f"{name}: observer", message=msg, hardware_id="switchobs",
                             values=ob),
            DiagnosticStatus(level=DiagnosticStatus.WARN if new_rej or new_lost or freq_problem
                             else DiagnosticStatus.OK,
                             name=f"{name}: inputs",
                             message="; ".join(x for x in (f"{new_rej} rejected in the last period" if new_rej else "",
                                                           f"{new_lost} lost in the last period" if new_lost else "",
                                                           freq_problem) if x) or "ok",
                             hardware_id="switchobs", values=inp),
        ]
        return arr

    def _configuration(self) -> list[KeyValue]:
        """The configuration status's values (static)."""
        pl = self.pipeline
        obs = pl.observer
        conf = [kv("system", pl.system.name), kv("fingerprint", pl.system.fingerprint()[:16]),
                kv("gain_table", str(pl.table_path)), kv("mode", pl.mode),
                kv("cycles", " ".join(c.label() for c in pl.cycles) or "robust"),
                kv("e0", obs.e0), kv("gain family", obs.family),
                kv("inputs", pl.specs_text or "paper interface"),
                kv("consistency check", "on" if pl.check else "off"),
                kv("reorder window (ms)", pl.window_ns * 1e-6)]
        if obs.noise is not None:
            conf.append(kv("noise model", obs.noise.describe()))
        if obs.kalman is not None:
            conf += [kv("kalman", obs.kalman.describe())]
        for k, d in enumerate(obs.designs if obs.gains.paper_envelope else ()):
            conf.append(kv(f"design[{k}].eta", d.eta))
            conf.append(kv(f"design[{k}].kappa", d.kappa))
            conf.append(kv(f"design[{k}].f (paper factors)", d.f))
        return conf

    def _observer(self, node: NodeState) -> list[KeyValue]:
        """The observer status's values: channel, cycle, gains, counters, cycles and residences."""
        pl = self.pipeline
        obs = pl.observer
        d = obs.current_design
        cyc = getattr(d, "cycle", None)
        ob = [kv("channel", obs.channel), kv("estimate time (s since origin)", obs.t),
              kv("current cycle tau", cyc.tau if cyc is not None else "robust"),
              kv("current cycle s", cyc.s if cyc is not None else "robust"),
              kv("current design index", obs.design_index),
              kv("updates", pl.updates), kv("partial updates", pl.partial_updates),
              kv("switches", pl.switches), kv("resets", pl.resets),
              kv("states set (~/set_state)", getattr(pl, "states_set", 0)),
              kv("estimates withheld (non-finite, then reset)", pl.nonfinite), kv("internal errors", pl.errors),
              kv("clock jumps back (resets)", node.clock_jumps_back),
              kv("clock jumps forward", node.clock_jumps_forward),
              kv("measurements ignored while inactive (lifecycle)", node.ignored_inactive)]
        if getattr(node, "published", None):
            ob.append(kv("messages published (optional outputs only while subscribed)",
                         ", ".join(f"{k} {v}" for k, v in node.published.items())))
        if obs.gains.paper_envelope:
            ob += [kv("current eta", d.eta), kv("current kappa", d.kappa),
                   kv("current gain norms |L_i|", gain_norms(d.L))]
        if obs.kalman is not None:
            ob += [kv("kalman table departures (online recursion)", obs.kalman_departures),
                   kv("kalman table re-locks", obs.kalman_relocks),
                   kv("kalman table gaps (missing samples served on the table's grid)", getattr(obs.gains, "gaps", 0)),
                   kv("kalman table gaps retired", getattr(obs.gains, "gaps_retired", 0)),
                   kv("kalman gains now", obs.gains_source)]
            if obs.kalman_fallback:
                ob.append(kv("last kalman departure", obs.kalman_fallback))
        if obs.covariance_withdrawn:
            ob.append(kv("covariance withdrawn (not published, no chi-square gate)", obs.covariance_withdrawn))
        if node.last_clock_jump:
            ob.append(kv("last clock jump", node.last_clock_jump))
        return ob + self._cycles()

    def _cycles(self) -> list[KeyValue]:
        """The last completed cycle and the active channel's residence, against the design."""
        recs = self.pipeline.observer.completed_cycles
        if recs:
            r = recs[-1]
            ob = [kv("cycles completed", len(recs)), kv("last cycle measured tau", r.tau),
                  kv("last cycle measured s", r.s), kv("last cycle measured h", r.h),
                  kv("last cycle paper factors f", r.f), kv("last cycle matched schedule", r.matched)]
            if r.a2_ok is not None:
                ob.append(kv("last cycle A2 held", r.a2_ok))
        else:
            ob = [kv("cycles completed", 0)]
        res = self.pipeline.residence()
        if res is not None:
            ob += [kv("active channel residence (s)", res.current),
                   kv(f"designed residence (s, {res.kind})", [res.lo, res.hi]),
                   kv("residence violations", res.violations)]
            if res.last is not None:
                ob.append(kv("last residence (channel, s)", [res.last[0], res.last[1]]))
            if res.f is not None:
                ob.append(kv("cycle so far paper factors f", res.f))
        return ob

    def _bounds(self) -> list[KeyValue]:
        """The published bounds now, or that they are withdrawn (none before the first sample)."""
        pl = self.pipeline
        obs = pl.observer
        if pl.origin_ns is None:
            return []
        env = obs.envelope()
        ob = [kv("paper bound", env.paper_bound),
              kv("exact bound" if env.noise_bound is not None else "exact bound (noise-free measurements)",
                 env.exact_bound if pl.bound_valid else "none (withdrawn)"),
              kv("exact bound valid", pl.bound_valid if pl.bound_valid else f"false ({pl.bound_invalid_why})")]
        if pl.bound_note:       # the bounds hold again, certified from data (switchobs_core.runtime.recovery)
            ob.append(kv("bounds", pl.bound_note))
        if env.noise_bound is not None:
            dist = "" if obs.disturbance is None else f", disturbance |w| <= {max(obs.disturbance.w_max):g}"
            ob.append(kv(f"noise bound (|v| <= {max(obs.noise_max):g} per row{dist})",
                         env.noise_bound if pl.bound_valid else "none (withdrawn)"))
        return ob

    def _model_against_data(self) -> list[KeyValue]:
        """The screening's and the attribution's counters (switchobs_ros.screening, .attribution)."""
        pl = self.pipeline
        ob = [kv("inconsistent samples (rejected, bounds withdrawn)", pl.inconsistent),
              kv("re-attributed samples", pl.reattributed),
              kv("late channel messages", pl.late_channel),
              kv("lost channel messages", pl.lost_channel),
              kv("samples in a loss named by the consistency test", pl.lost_channel_named),
              kv("samples near a switching instant (channel rows dropped)", pl.near_switch),
              kv("samples not proven within the reorder window (channel rows dropped)", pl.uncertain),
              kv("samples not proven within the reorder window, named by the consistency test", pl.uncertain_named),
              kv("outliers (chi-square gate)", pl.outliers if pl.chi2_alpha > 0 else "gate off"),
              kv("bias alarms (CUSUM)", pl.bias_alarms),
              kv("model failures (a body the gate starved)", pl.model_failures),
              kv("re-certifications from data", pl.recertifications),
              kv("clock tolerance (ms)", pl.clocks.tol * 1e-6)]
        # each source's least receive - stamp over its recent messages: negative proves its clock
        # ahead of the estimator's (switchobs_ros.clocks)
        ob += [kv(f"clock: {t} least latency (ms; negative: ahead)", v) for t, v in pl.clocks.offsets_ms().items()]
        ob += [kv(f"clock: {t} ahead beyond the tolerance (ms)", v * 1e-6) for t, v in pl.clocks.skewed.items()]
        if pl.last_inconsistency:
            ob.append(kv("last inconsistency", pl.last_inconsistency))
        if pl.last_alarm:
            ob.append(kv("last alarm", pl.last_alarm))
        return ob

    def _observer_status(self, now_ns: int, node: NodeState, ob: list[KeyValue]) -> tuple[int, str]:
        """The observer status's level and message; appends the measurement age and the outage
        prediction to ``ob``."""
        pl = self.pipeline
        level, msg = DiagnosticStatus.OK, "estimating"
        if pl.last_accept_clock_ns is None:
            level, msg = DiagnosticStatus.WARN, "waiting for measurements"
        else:
            age = (now_ns - pl.last_accept_clock_ns) * 1e-9
            ob.append(kv("seconds since last measurement", age))
            if age > node.sensor_timeout:
                level = DiagnosticStatus.WARN
                msg = f"no measurement for {age:.2f} s (sensor_timeout {node.sensor_timeout} s)"
            if age > node.sensor_timeout and node.last_prediction is not None \
                    and node.last_prediction.stamp_ns > (pl.obs_ns or 0):
                ob += [kv("outage: predicting (last innovation held), exact bound", node.last_prediction.exact_bound),
                       kv("outage predictions published", node.predictions)]
        if not pl.bound_valid and (pl.inconsistent or pl.late_channel or pl.lost_channel or pl.bias_alarms
                                   or pl.model_failures or pl.clocks.skewed):
            level = max(level, DiagnosticStatus.WARN)
            msg += f"; bounds withdrawn: {pl.bound_invalid_why}"
        recs = pl.observer.completed_cycles
        if recs and not recs[-1].matched:
            level = max(level, DiagnosticStatus.WARN)
            msg += "; last cycle did not match the schedule"
        if pl.observer.covariance_withdrawn:
            level = max(level, DiagnosticStatus.WARN)
            msg += "; covariance withdrawn: the Riccati recursion ran out of digits"
        res = pl.residence()
        if res is not None and res.problem:
            level = max(level, DiagnosticStatus.WARN)
            msg += f"; {res.problem}"
        return level, msg

    def _inputs(self, now_ns: int) -> tuple[list[KeyValue], int, int, str]:
        """The inputs status's values (rates over the last period on the node clock, accepted,
        lost and rejected counts), the rejections and losses new in the period, and the frequency
        problem ('' if none); starts the next period."""
        pl = self.pipeline
        t0_ns, acc0, _, upd0, _ = self._rate_base
        dt = (now_ns - t0_ns) * 1e-9
        inp = []
        rates = {}
        total_lost = 0
        wrong: list[str] = []
        for topic in pl.input_topics:
            rates[topic] = rate = (pl.accepted[topic] - acc0[topic]) / dt if dt > 0 else 0.0
            inp.append(kv(f"{topic} rate (Hz)", rate))
            inp.append(kv(f"{topic} accepted", pl.accepted[topic]))
            # messages the publisher's sequence numbers show never arrived (switchobs_ros.loss)
            lost = pl.lost_channel if topic == pl.channel_topic else pl.loss.lost[topic]
            total_lost += lost
            inp.append(kv(f"{topic} lost", lost))
            if pl.loss.restarts[topic]:
                inp.append(kv(f"{topic} publisher restarts", pl.loss.restarts[topic]))
            if pl.loss.wrong_type[topic]:
                wrong.append(f"{topic} has {pl.loss.wrong_type[topic]} publisher(s) of another type "
                             f"({pl.loss.wrong_type_names.get(topic, 'unknown')}): not received")
                inp.append(kv(f"{topic} publishers of another type", pl.loss.wrong_type[topic]))
                inp.append(kv(f"{topic} other types", pl.loss.wrong_type_names.get(topic, "unknown")))
        # frequency status (as robot_localization's): measured against the expected rate
        out_rate = (pl.updates - upd0) / dt if dt > 0 else 0.0
        expected = float(getattr(pl, "config", None)["rate"]) if getattr(pl, "config", None) is not None else 0.0
        inp.append(kv("estimates published rate (Hz)", out_rate))
        inp.append(kv("expected measurement rate (Hz)", expected if expected > 0 else "not set (parameter rate)"))
        freq_problem = "; ".join([*wrong, self._frequency_problem(expected, t0_ns, rates, out_rate)]).strip("; ")
        inp.append(kv("frequency status", freq_problem or ("ok" if expected > 0 else "not checked (no rate)")))
        total_rej = sum(pl.rejected.values())
        for (topic, reason), n in sorted(pl.rejected.items()):
            inp.append(kv(f"rejected {topic} {reason}", n))
        inp.append(kv("rejected total", total_rej))
        if pl.last_rejection:
            inp.append(kv("last rejection", pl.last_rejection))
        new_rej = total_rej - self._rate_base[2]
        new_lost = total_lost - self._rate_base[4]
        self._rate_base = (now_ns, Counter(pl.accepted), total_rej, pl.updates, total_lost)
        return inp, new_rej, new_lost, freq_problem

    def _frequency_problem(self, expected: float, t0_ns: int, rates: dict[str, float], out_rate: float) -> str:
        """The input or output rate outside :data:`FREQUENCY_TOLERANCE` of the expected one ('' if
        none, or no full period yet)."""
        if not (expected > 0 and t0_ns > self._t_first_ns):
            return ""
        pl = self.pipeline
        lo, hi = FREQUENCY_TOLERANCE
        # the channel-specific topics together carry one message per tick (the shared ones too)
        own = [s.topic for s in pl.sources if not s.shared] or [pl.sources[0].topic]
        for what, r in ((" + ".join(own), sum(rates[t] for t in own)), ("estimates", out_rate)):
            if not lo * expected <= r <= hi * expected:
                return (f"{what} at {r:.1f} Hz, outside [{lo * expected:.1f}, {hi * expected:.1f}] Hz "
                        f"(expected {expected:g} Hz)")
        return ""
