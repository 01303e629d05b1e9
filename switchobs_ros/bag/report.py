"""``switchobs_bag report``: error against the truth, the bounds and the channel, from a bag.

Input: a bag with the estimator's outputs (``<node>/state``, ``<node>/envelope``), recorded live
or written by ``switchobs_bag estimate``; with ``/sim/truth`` if present, and the channel signal
and ``/diagnostics`` if present.

The channel signal (for the shading and the cycles) comes from the system's input
specification (``inputs``: :class:`msg_bridge.InputSpecs`): its channel topic, or, for a system
with one topic per channel and no channel topic, the samples of those topics (each sample says
its topic's channel is active). Without a specification the paper interface's
``/camera/active_channel`` is used if the bag has it; with no channel signal at all the number of
cycles is unknown (``None``, "n/a"), never 0.

Estimates and truth are matched by stamp (the stamp every labelled array carries). Messages
are read in the order written (receive order). A bag of a looped replay holds several passes
(the stamps start over): each pass is reported on its own.

Outputs: a PNG (top: ``||x_hat - x||``, the paper's bound and the exact bound on a log scale
with agent 2's residence intervals shaded; bottom: the active channel), and a summary: per
pass the error at the first estimate (after the first sample's update) and the final error, the
per-cycle error ratio (the error at each cycle end over the error at the previous cycle end; a
cycle ends where the channel goes back to channel 1; cycles that start at the rounding floor,
below :data:`FLOOR` of the first error, are left out), and the rejected inputs reported in the
last ``/diagnostics`` of the estimator.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

import msg_bridge as mb
from switchobs_core.files import write_with
from switchobs_core.numerics.norms import error_norm

from .io import CHANNEL_TYPES, BagError, BagIn, channel_message, deserialize

__all__ = ["PassSummary", "Report", "load_report", "plot_report"]


@dataclass
class PassSummary:
    """One pass over the data (a looped replay has several)."""

    t: np.ndarray                      # s since the pass's first estimate
    stamps: np.ndarray                 # ns
    err: np.ndarray | None             # ||x_hat - x|| at stamps with a truth (nan where none)
    paper: np.ndarray
    exact: np.ndarray
    channel_t: np.ndarray              # channel signal (s since the pass start)
    channel: np.ndarray
    cycle_ends: list | None = field(default_factory=list)     # s; None: no channel signal in the bag
    cycle_err: list = field(default_factory=list)      # error at each cycle end
    contraction: list = field(default_factory=list)    # ratio to the previous cycle end
    noise: np.ndarray | None = None    # noise_bound (a declared noise bound), else None

    def violations(self, bound: np.ndarray | None) -> int | None:
        """Estimates whose error exceeds ``bound`` (relative tolerance 1e-9; None without truth or
        bound; estimates without a known bound, after a reset, are not counted)."""
        if self.err is None or bound is None:
            return None
        ok = np.isfinite(self.err) & (bound > 0)
        return int(np.sum(self.err[ok] > bound[ok] * (1 + 1e-9) + 1e-300))

    @property
    def e_first(self) -> float:
        return float(self.err[np.isfinite(self.err)][0]) if self.err is not None and np.isfinite(self.err).any() \
            else float("nan")

    @property
    def e_final(self) -> float:
        return float(self.err[np.isfinite(self.err)][-1]) if self.err is not None and np.isfinite(self.err).any() \
            else float("nan")


@dataclass
class Report:
    bag: str
    passes: list
    rejected: dict
    n_estimates: int
    has_truth: bool


def _labelled(bag_msgs, topic, cls, pick: tuple[str, ...] = ()):
    """``(log_ns, stamp_ns, values)`` of a labelled-array topic; with ``pick`` only the elements
    of those labels, in that order (nan where a message lacks one)."""
    out = []
    for m in bag_msgs:
        if m.topic == topic:
            try:
                a = mb.unpack_labelled(deserialize(m, cls))
            except mb.BridgeError as err:       # e.g. an infinite stamp
                raise BagError(f"{topic}: the message logged at {m.log_ns} ns: {err}") from None
            vals = a.values
            if pick:
                where = {lab: i for i, lab in enumerate(a.labels)}
                vals = np.array([vals[where[p]] if p in where else np.nan for p in pick])
            out.append((m.log_ns, a.stamp_ns, vals))
    return out


def _split_passes(series, indices: bool = False):
    """Split ``(log_ns, stamp_ns, values)`` in file order where the stamp goes back (a looped
    replay): lists of indices, or one ``{stamp: values}`` dict per pass."""
    passes: list = [[]]
    last = None
    for i, (_, s, _) in enumerate(series):
        if last is not None and s <= last:
            passes.append([])
        passes[-1].append(i)
        last = s
    if indices:
        return passes
    return [{series[i][1]: series[i][2] for i in idx} for idx in passes if idx]


def _channel_sources(inputs) -> tuple[str | None, dict[str, int]]:
    """``(channel topic, {per-channel topic: channel})``, absolute names, of an input specification
    (None: the paper interface's ``/camera/active_channel``, no per-channel topics)."""
    if inputs is None:
        return "/camera/active_channel", {}
    absolute = lambda topic: "/" + topic.strip("/")
    per_channel = {absolute(s.topic): s.channel for s in inputs.sources if s.channel is not None}
    return (absolute(inputs.channel_topic) if inputs.channel_topic else None), per_channel


def load_report(bag_path, node: str = "/estimator", inputs=None) -> Report:
    """Read the bag and compute the per-pass series and summary.

    ``inputs``: the system's :class:`msg_bridge.InputSpecs` (where the channel signal comes from,
    module docstring); None: the paper interface's channel topic.
    """
    from diagnostic_msgs.msg import DiagnosticArray
    from std_msgs.msg import Float64MultiArray

    node = "/" + node.strip("/")
    t_state, t_env = f"{node}/state", f"{node}/envelope"
    with BagIn(bag_path) as bag:
        bag.require({t_state: "std_msgs/msg/Float64MultiArray", t_env: "std_msgs/msg/Float64MultiArray"},
                    " (the estimator's outputs: record them, or run `switchobs_bag estimate`)")
        t_chan, per_channel = _channel_sources(inputs)
        opt = {"/sim/truth": "std_msgs/msg/Float64MultiArray", "/diagnostics": "diagnostic_msgs/msg/DiagnosticArray"}
        if t_chan:
            opt[t_chan] = CHANNEL_TYPES
        present = [t for t in opt if t in bag.topics]
        bag.require({t: opt[t] for t in present})
        per_channel = {t: c for t, c in per_channel.items() if t in bag.topics}
        msgs = bag.messages([t_state, t_env, *present, *per_channel], order="file")
    states = _labelled(msgs, t_state, Float64MultiArray)
    env_passes = _split_passes(_labelled(msgs, t_env, Float64MultiArray, ("paper_bound", "exact_bound", "noise_bound")))
    truth = {s: v for _, s, v in _labelled(msgs, "/sim/truth", Float64MultiArray)}
    has_channel = t_chan in present or bool(per_channel)
    chan = [(m.log_ns, mb.channel_value(channel_message(m)) if m.topic == t_chan else per_channel[m.topic])
            for m in msgs if m.topic == t_chan or m.topic in per_channel]
    if not states:
        raise BagError(f"bag {bag_path}: topic {t_state} has no messages")
    rejected: dict[str, int] = {}
    for m in msgs:
        if m.topic == "/diagnostics":
            arr = deserialize(m, DiagnosticArray)
            for st in arr.status:
                if st.name.startswith(node + ":"):
                    for kv in st.values:
                        if kv.key.startswith("rejected ") and kv.key != "rejected total":
                            rejected[kv.key[len("rejected "):]] = int(kv.value)
    # split into passes where the stamps go back (a looped replay); the envelopes likewise, so
    # that each pass is matched with its own envelopes (the stamps repeat from pass to pass)
    passes_idx = _split_passes(states, indices=True)
    passes = []
    for k_pass, idx in enumerate(passes_idx):
        envs = env_passes[k_pass] if k_pass < len(env_passes) else {}
        log0, log1 = states[idx[0]][0], states[idx[-1]][0]
        stamps = np.array([states[i][1] for i in idx], dtype=np.int64)
        t = (stamps - stamps[0]) * 1e-9
        err = None
        if truth:
            err = np.array([error_norm(states[i][2], truth[states[i][1]]) if states[i][1] in truth else np.nan
                            for i in idx])
        env = np.array([envs.get(states[i][1], np.full(3, np.nan)) for i in idx])
        ch = [(ln, c) for ln, c in chan if log0 - 1 <= ln <= log1]
        ct = np.array([(ln - log0) * 1e-9 + t[0] for ln, _ in ch]) if ch else np.zeros(0)
        cv = np.array([c for _, c in ch]) if ch else np.zeros(0, dtype=int)
        p = PassSummary(t=t, stamps=stamps, err=err, paper=env[:, 0], exact=env[:, 1], channel_t=ct, channel=cv,
                        noise=env[:, 2] if np.isfinite(env[:, 2]).any() else None)
        # cycle ends: the channel goes back to 1
        if not has_channel:
            p.cycle_ends = None
        for k in range(1, len(cv)):
            if cv[k] == 1 and cv[k - 1] != 1:
                p.cycle_ends.append(float(ct[k]))
        if err is not None and p.cycle_ends is not None:
            for te in p.cycle_ends:
                j = int(np.searchsorted(t, te - 1e-9))
                j = min(max(j - 1, 0), len(t) - 1)      # the last estimate of the ending cycle
                p.cycle_err.append(float(err[j]))
            p.contraction = [b / a if a > 0 else float("nan") for a, b in zip(p.cycle_err, p.cycle_err[1:])]
        passes.append(p)
    return Report(bag=str(bag_path), passes=passes, rejected=rejected, n_estimates=len(states),
                  has_truth=bool(truth))


#: Cycles whose starting error is below this fraction of the first estimate's error are left out of the
#: error ratios: at the rounding floor the error's ratios are noise (5.47 per cycle at 1e-15 is not divergence).
FLOOR = 1e-9


def converging(p: Any) -> list[float]:
    """The pass's per-cycle error ratios (finite), of the cycles starting above :data:`FLOOR` of its first error."""
    e0 = p.e_first
    return [r for a, r in zip(p.cycle_err, p.contraction) if np.isfinite(r) and np.isfinite(e0) and a > FLOOR * e0]


def summary_table(rep: Report) -> str:
    """A Markdown summary of the report."""
    lines = [f"Bag `{rep.bag}`: {rep.n_estimates} estimates in {len(rep.passes)} pass(es); "
             f"truth {'present' if rep.has_truth else 'absent (no error, bounds only)'}.", "",
             "| pass | estimates | span [s] | error at the first estimate | final error "
             "| final exact bound (noise-free) | samples above it | final noise bound | samples above it "
             "| final paper bound (claim) | cycles | median error ratio per cycle | largest error ratio per cycle |",
             "|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]

    def num(v: float, f: str = ".3e") -> str:
        return format(v, f) if np.isfinite(v) else "n/a"

    def count(v: int | None) -> str:
        return "n/a" if v is None else str(v)

    for k, p in enumerate(rep.passes, 1):
        c = np.array(converging(p))
        exact = f"{p.exact[-1]:.3e}" if p.exact[-1] > 0 else "none (after a reset)"
        noise = "not declared" if p.noise is None else (f"{p.noise[-1]:.3e}" if p.noise[-1] > 0 else "none")
        paper = f"{p.paper[-1]:.3e}" if p.paper[-1] >= 0 else "n/a"     # -1: not applicable (Kalman gains)
        lines.append(f"| {k} | {len(p.t)} | {p.t[-1]:.2f} | {num(p.e_first)} | {num(p.e_final)} | {exact} "
                     f"| {count(p.violations(p.exact))} | {noise} | {count(p.violations(p.noise))} "
                     f"| {paper} | {'n/a' if p.cycle_ends is None else len(p.cycle_ends)} "
                     f"| {num(np.median(c), '.3g') if c.size else 'n/a'} "
                     f"| {num(np.max(c), '.3g') if c.size else 'n/a'} |")
    lines += ["", "The exact bound holds for noise-free measurements (it counts the estimator's rounding); with "
              "noisy measurements it is exceeded and only a declared noise bound (parameter noise.max) is a "
              "guarantee. The paper's bound is the paper's claim.",
              "", "Error at the first estimate: after the first sample's update (the error before it is the initial "
              "estimate's, which e0 bounds). Error ratio per cycle: the error at a cycle's end over the error at the "
              f"previous cycle's end (< 1: it shrank), over the cycles that start above {FLOOR:g} of the first "
              "error: below that the error is at the rounding (or noise) floor, where ratios are noise, not "
              "divergence."]
    if any(p.cycle_ends is None for p in rep.passes):
        lines += ["", "Cycles: n/a: the bag holds no channel signal (no channel topic, no per-channel topic of the "
                  "system's inputs); pass --system (and --inputs) of the estimated system."]
    lines += ["", "Rejected inputs (estimator diagnostics): " +
              (", ".join(f"{k}: {v}" for k, v in sorted(rep.rejected.items())) if rep.rejected else "none")]
    if rep.passes and rep.passes[0].cycle_err:
        p = rep.passes[-1]
        lines += ["", "Per-cycle error at cycle ends (last pass): " +
                  ", ".join(f"{e:.2e}" for e in p.cycle_err[:12]) + (" ..." if len(p.cycle_err) > 12 else "")]
    return "\n".join(lines)


def plot_report(rep: Report, png: str | Path, title: str = "") -> None:
    """The PNG: error and bounds (log) over the channel signal, one column per pass (at most 3)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    passes = rep.passes[:3]
    fig, axes = plt.subplots(2, len(passes), figsize=(9.5 if len(passes) == 1 else 6 * len(passes), 6.2),
                             gridspec_kw={"height_ratios": [4, 1]}, sharex="col", squeeze=False,
                             constrained_layout=True)
    for k, p in enumerate(passes):
        ax, axc = axes[0, k], axes[1, k]
        ax.semilogy(p.t, p.paper, color="tab:orange", lw=1.6, label="paper's bound $\\alpha\\sum_i z_i$ (claimed)")
        # exact_bound = -1 after a reset of the estimator: no bound is known (pipeline.NO_BOUND)
        known = p.exact > 0
        nv = p.violations(p.exact)
        verdict = "" if nv is None else (", held at every estimate" if nv == 0 else
                                         f", exceeded at {nv} estimates: the measurements are noisy")
        ax.semilogy(p.t, np.where(known, p.exact, np.nan), color="tab:green", lw=1.6, ls="--",
                    label=f"exact bound $\\|\\Phi(t,t_0)\\|\\,e_0$ (noise-free measurements{verdict})"
                    if known.any() else "exact bound: none after a reset (the initial error is unknown)")
        if p.noise is not None:
            nn = p.violations(p.noise)
            ax.semilogy(p.t, np.where(p.noise > 0, p.noise, np.nan), color="tab:purple", lw=1.4, ls="-.",
                        label="noise bound (declared noise.max): guaranteed"
                        + ("" if nn is None else ", held" if nn == 0 else f", EXCEEDED at {nn} estimates"))
        if p.err is not None:
            ax.semilogy(p.t, p.err, color="tab:blue", lw=1.3, label="$\\|\\hat x - x\\|$ (estimate vs truth)")
            if p.cycle_ends and p.cycle_err:
                ax.plot(p.cycle_ends[:len(p.cycle_err)], p.cycle_err, "o", ms=3.5, color="tab:blue", mfc="white",
                        label="error at cycle ends")
        # agent 2 (channel != 1) shaded
        if len(p.channel):
            on = None
            for tc, c in zip(np.append(p.channel_t, p.t[-1]), np.append(p.channel, 1)):
                if c != 1 and on is None:
                    on = tc
                elif c == 1 and on is not None:
                    ax.axvspan(on, tc, color="0.92", lw=0, zorder=0)
                    axc.axvspan(on, tc, color="0.92", lw=0, zorder=0)
                    on = None
            axc.step(p.channel_t, p.channel, where="post", color="0.25", lw=1.2)
            axc.set_yticks(sorted(set(int(c) for c in p.channel)))
        axc.set_ylabel("channel")
        axc.set_xlabel("time since the first estimate [s]")
        vals = [v for v in (p.paper, p.exact, p.err, p.noise) if v is not None]
        finite = np.concatenate([v[np.isfinite(v) & (v > 0)] for v in vals])
        if finite.size:     # (a bound near the largest double: no room above it)
            ax.set_ylim(max(finite.min() / 3, 1e-12), min(finite.max() * 3, 1e300) if finite.max() < 1e300
                        else finite.max())
        ax.set_xlim(p.t[0], p.t[-1])
        ax.grid(True, which="major", alpha=0.4)
        ax.grid(True, which="minor", alpha=0.12)
        ax.set_ylabel("estimation error norm")
        sub = f"pass {k + 1}: " if len(rep.passes) > 1 else ""
        if p.err is not None:
            c = converging(p)
            con = f", median error ratio per cycle {np.median(c):.3f}" if c else ""
            ax.set_title(f"{sub}error {p.e_first:.2e} -> {p.e_final:.2e}{con}", fontsize=10)
        else:
            ax.set_title(f"{sub}no truth in the bag: bounds only", fontsize=10)
        if k == 0:
            ax.legend(loc="lower left", fontsize=8.5, framealpha=0.95)
    fig.suptitle(title or f"switchobs: {Path(rep.bag).name} (agent 2 in view shaded)", fontsize=11)
    try:
        write_with(png, "report", lambda q: fig.savefig(q, dpi=120), exc=BagError)
    finally:
        plt.close(fig)
