"""The demo: estimator and camera_sim as separate processes over DDS on localhost.

``python -m tools.demo [--schedule periodic|sequence] [--duration 30] [--out DIR]``

camera_sim simulates the paper's camera + 2 agents and is the clock (``/clock``, faster than
real time by ``--time-scale``); the estimator runs with ``use_sim_time``. The demo listens to
``/estimator/state``, ``/estimator/envelope`` and ``/sim/truth``, prints ``||x_hat - x||`` at
the end of every switching cycle, and writes ``error.png`` (the error, the paper's bound and
the exact bound, on a log scale, with the active channel) and ``error.csv``.

Initialisation as in the paper: ``x_hat(0) = x(0) + 0.1 randn`` (seeded), ``e0 = ||x_tilde(0)||``.
"""

from __future__ import annotations

import os
import signal
import sys


def _interrupted_early(signum, frame) -> None:
    """Ctrl-C before any node runs (while the heavy imports load): one line, exit 130. os._exit,
    because an exception raised in the middle of an import prints the import's traceback."""
    print("demo: interrupted", file=sys.stderr, flush=True)
    os._exit(130)


if __name__ == "__main__":
    signal.signal(signal.SIGINT, _interrupted_early)

import argparse  # noqa: E402
import math  # noqa: E402
import tempfile  # noqa: E402
import threading  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
import rclpy  # noqa: E402
from rclpy.signals import SignalHandlerOptions  # noqa: E402

from switchobs_core.cli._common import OneLineParser  # noqa: E402
from switchobs_ros.core_config import DEFAULT_X0  # noqa: E402
from tools.domain import claim_domain  # noqa: E402
from tools.launch import Collector, NodeProcess, ros_args  # noqa: E402

SCHEDULES = {
    "periodic": {"schedule.mode": "periodic", "schedule.tau": [2.0], "schedule.s": [0.6]},
    "sequence": {"schedule.mode": "sequence", "schedule.tau": [4.0, 3.0, 3.0, 2.0],
                 "schedule.s": [0.5, 0.6, 0.6, 0.4]},
}


def run(schedule: str = "periodic", duration: float = 30.0, time_scale: float = 2.0, rate: float = 100.0,
        init: str = "paper", seed: int = 0, out: Path | None = None, gain_table: str = "",
        quiet: bool = False, extra_estimator: dict | None = None, noise_std: float = 0.0,
        schedule_params: dict | None = None, process_noise: float = 0.0, system: str = "paper",
        initial_state: tuple | None = None, extra_camera: dict | None = None,
        camera_env: dict | None = None) -> dict:
    """Run the demo; return the collected series (stamps in s from the first tick).

    ``schedule_params`` (``schedule.mode/tau/s``) replaces the named ``schedule``;
    ``process_noise`` is camera_sim's plant noise q (Qc = q^2 I). ``system`` is any system
    (a scenario or a YAML file with an ``inputs:`` section): both nodes use it, camera_sim
    starting from ``initial_state`` (default: the paper's scene). ``extra_camera`` overrides
    camera_sim's parameters (``publish_clock: False`` runs both nodes on the system clock);
    ``camera_env`` adds to camera_sim's environment (e.g. a preloaded clock offset)."""
    stop = _InterruptFlag()
    try:
        return _run(stop, schedule, duration, time_scale, rate, init, seed, out, gain_table, quiet,
                    extra_estimator, noise_std, schedule_params, process_noise, system, initial_state,
                    extra_camera, camera_env)
    finally:
        stop.restore()


def _run(stop: _InterruptFlag, schedule: str, duration: float, time_scale: float, rate: float, init: str,
         seed: int, out: Path | None, gain_table: str, quiet: bool, extra_estimator: dict | None,
         noise_std: float, schedule_params: dict | None, process_noise: float, system: str = "paper",
         initial_state: tuple | None = None, extra_camera: dict | None = None,
         camera_env: dict | None = None) -> dict:
    lease = None
    if "ROS_DOMAIN_ID" not in os.environ or os.environ.get("SWITCHOBS_CLAIM_DOMAIN", "1") == "1":
        lease = claim_domain()
        os.environ["ROS_DOMAIN_ID"] = str(lease.domain_id)
    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    if not quiet:
        dom = os.environ["ROS_DOMAIN_ID"]
        print(f"demo: ROS_DOMAIN_ID={dom} (to watch from another shell: export ROS_DOMAIN_ID={dom} "
              "ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST)", flush=True)
    out = Path(out) if out else None
    if out:
        out.mkdir(parents=True, exist_ok=True)
    x0 = np.array(DEFAULT_X0 if initial_state is None else initial_state, dtype=float)
    if init == "paper":
        xhat0 = x0 + 0.1 * np.random.default_rng(seed).standard_normal(x0.size)
    else:
        xhat0 = np.zeros_like(x0)
    e0 = float(np.linalg.norm(xhat0 - x0))
    sched = dict(schedule_params) if schedule_params else SCHEDULES[schedule]
    est_params = dict(sched, initial_estimate=list(map(float, xhat0)), e0=e0, use_sim_time=True,
                      gain_table=gain_table, system=system)
    est_params.update(extra_estimator or {})
    cam_params = dict(sched, rate=rate, duration=duration, publish_clock=True, time_scale=time_scale,
                      wait_for_subscribers=1, wait_for_truth_subscribers=1, seed=seed, noise_std=float(noise_std),
                      process_noise=float(process_noise), system=system, initial_state=list(map(float, x0)))
    cam_params.update(extra_camera or {})
    if not cam_params["publish_clock"]:
        est_params["use_sim_time"] = False
    rclpy.init(signal_handler_options=SignalHandlerOptions.NO)
    node = Collector(["/estimator/state", "/estimator/envelope", "/sim/truth"], name="switchobs_demo")
    est = cam = None
    logs = out or Path(tempfile.mkdtemp(prefix="switchobs_demo_"))
    try:
        est = NodeProcess("estimator", ros_args(params=est_params), log=logs / "estimator.log")
        deadline = time.monotonic() + 120
        while not node.matched(["/estimator/state"]):       # the estimator is up (design at start-up may take a while)
            stop.check()
            rclpy.spin_once(node, timeout_sec=0.1)
            if not est.alive():
                raise RuntimeError(f"estimator exited with {est.proc.returncode}:\n{est.output()}")
            if time.monotonic() > deadline:
                raise RuntimeError("estimator did not come up within 120 s")
        cam = NodeProcess("camera_sim", ros_args(params=cam_params), log=logs / "camera_sim.log",
                          env=None if camera_env is None else {**os.environ, **camera_env})
        t_wall = time.monotonic()
        live = _LiveRows(sched, e0, quiet, noise_std)
        while cam.alive():
            stop.check()
            rclpy.spin_once(node, timeout_sec=0.05)
            live.update(node)
        t_end = time.monotonic() + 1.0
        while time.monotonic() < t_end:  # the last answers
            stop.check()
            rclpy.spin_once(node, timeout_sec=0.05)
        live.update(node, final=True)
        wall = time.monotonic() - t_wall
        if cam.proc.returncode != 0:
            raise RuntimeError(f"camera_sim exited with {cam.proc.returncode}:\n{cam.output()}")
    except RuntimeError:
        if stop.hit:        # a node that died of the same Ctrl-C (e.g. mid-import) is the interrupt, not a failure
            raise KeyboardInterrupt from None
        raise
    finally:
        for p in (cam, est):
            if p is not None:
                p.stop()
        node.destroy_node()
        rclpy.try_shutdown()
        if lease is not None:
            lease.release()
    res = _series(node, e0)
    res.update(schedule=schedule, duration=duration, wall=wall, e0=e0, time_scale=time_scale, rate=rate,
               noise=float(noise_std), system=system)
    res["failures"] = verdict(res)
    if not quiet:
        _report(res, sched)
    if out:
        _write(res, out, sched)
    return res


class _InterruptFlag:
    """SIGINT (Ctrl-C) sets a flag that the demo's loops check, so the interrupt surfaces as one
    KeyboardInterrupt at a known place. With rclpy's own handler (or Python's default) the exception
    is raised wherever the main thread happens to be, e.g. inside an rclpy ``Future.__del__``, where
    Python swallows it ("Exception ignored in ...") while the context is already shut down: the demo
    then failed with "failed to create timer: context is not valid" instead of stopping."""

    def __init__(self) -> None:
        self.hit = False
        self._old = None
        if threading.current_thread() is threading.main_thread():   # signal handlers live in the main thread
            self._old = signal.signal(signal.SIGINT, self._set)

    def _set(self, signum, frame) -> None:
        self.hit = True

    def check(self) -> None:
        if self.hit:
            raise KeyboardInterrupt

    def restore(self) -> None:
        if self._old is not None:
            signal.signal(signal.SIGINT, self._old)


def _series(node: Collector, e0: float) -> dict:
    truth = node.data["/sim/truth"]
    state = node.data["/estimator/state"]
    env = node.data["/estimator/envelope"]
    common = sorted(set(truth) & set(state))
    if not common:
        raise RuntimeError("no estimate matched a truth stamp")
    t0 = min(truth)
    t = np.array([(s - t0) * 1e-9 for s in common])
    err = np.array([np.linalg.norm(state[s] - truth[s]) for s in common])
    envs = np.array([env.get(s, np.full(4, np.nan)) for s in common])
    return {"t": t, "err": err, "paper": envs[:, -2], "exact": envs[:, -1], "stamps": common,
            "n_truth": len(truth), "n_state": len(state), "n_env": len(env)}


#: Noise-free demo: the final error must be below this fraction of the initial error.
FINAL_FRACTION = 1e-4


def verdict(res: dict) -> list[str]:
    """Why the demo failed (empty: it did not): noise-free, a published estimate above the
    published exact bound (a guarantee for noise-free samples, rounding included: it must never
    happen), or a final error not below :data:`FINAL_FRACTION` of the initial one. A withdrawn
    bound (-1: the estimator found a sample inconsistent with the model) is no failure of the
    guarantee but is reported by :func:`_report`."""
    if res.get("noise", 0.0) > 0:
        return []
    t, err, exact = res["t"], res["err"], res["exact"]
    out = []
    valid = exact > 0
    above = valid & (err > exact * (1 + 1e-9))
    if above.any():
        out.append(f"{int(above.sum())} of {int(valid.sum())} published estimates are above the published exact bound "
                   f"(a guarantee for these noise-free samples), the first at t = {t[above][0]:.2f} s")
    if not err[-1] < FINAL_FRACTION * res["e0"]:
        out.append(f"the final error {err[-1]:.3g} is not below {FINAL_FRACTION:g} of the initial error "
                   f"{res['e0']:.3g}")
    return out


def _cycle_ends(sched: dict, t_end: float) -> list[float]:
    taus = sched["schedule.tau"]
    out, t, k = [], 0.0, 0
    while True:
        t += taus[k % len(taus)]
        if t > t_end + 1e-9:
            return out
        out.append(t)
        k += 1


class _LiveRows:
    """One line per switching cycle while the demo runs (printed once the cycle's end is past in
    the truth stream and its estimate has arrived)."""

    def __init__(self, sched: dict, e0: float, quiet: bool, noise: float):
        self.sched, self.e0, self.quiet, self.noise = sched, e0, quiet, noise
        self.done = 0
        self.t0: int | None = None

    def update(self, node: Collector, final: bool = False) -> None:
        if self.quiet:
            return
        truth, state, env = node.data["/sim/truth"], node.data["/estimator/state"], node.data["/estimator/envelope"]
        if not truth or not state:
            return
        if self.t0 is None:
            self.t0 = min(truth)
            print(f"initial error ||x_hat(0) - x(0)|| = {self.e0:.4f} (known here because the simulation knows "
                  "x(0); on a robot e0 is a declared bound)")
            if self.noise > 0:
                print(f"measurement noise std {self.noise:g}: the exact bound is the noise-free bound, printed for "
                      "reference, not as a guarantee")
            print(f"{'cycle':>5} {'t [s]':>7} {'||x_hat - x||':>14} {'relative':>10} {'paper bound':>12} "
                  f"{'exact bound':>12}", flush=True)
        latest = (max(state) - self.t0) * 1e-9
        ends = _cycle_ends(self.sched, latest + (1.0 if final else 0.0))
        for te in ends[self.done:]:
            if not final and te > latest - 0.05:
                break
            s = self.t0 + round(te * 1e9)
            stamps = [x for x in state if x <= s and x in truth]
            if not stamps:
                break
            s = max(stamps)
            err = float(np.linalg.norm(state[s] - truth[s]))
            e = env.get(s, np.full(4, np.nan))
            self.done += 1
            print(f"{self.done:>5} {(s - self.t0) * 1e-9:>7.2f} {err:>14.3e} {err / self.e0:>10.2e} "
                  + (f"{e[-2]:>12.3e}" if e[-2] > 0 else f"{'n/a':>12}") + f" {e[-1]:>12.3e}", flush=True)


def _report(res: dict, sched: dict) -> None:
    t, err = res["t"], res["err"]
    print(f"switchobs demo: schedule {_schedule_text(res['schedule'], sched)}, {res['duration']:g} s simulated in "
          f"{res['wall']:.1f} s wall ({res['rate']:g} Hz); {res['n_state']} estimates for {res['n_truth']} truth "
          "samples")
    print(f"final: t = {t[-1]:.2f} s, ||x_hat - x|| = {err[-1]:.3e} ({err[-1] / res['e0']:.2e} of the initial error)")
    withdrawn = res["exact"] < 0
    if withdrawn.any():
        print(f"bounds withdrawn by the estimator from t = {t[withdrawn][0]:.2f} s (a sample inconsistent with the "
              "model; see estimator.log)")


def _schedule_text(name: str, sched: dict) -> str:
    """``periodic (tau 2 s, s 0.6)`` / ``sequence ((4 s, 0.5), (3 s, 0.6), ...)``."""
    pairs = list(zip(sched["schedule.tau"], sched["schedule.s"]))
    dead = f", dead time {sched['schedule.dead_time']:g} s" if sched.get("schedule.dead_time") else ""
    if len(pairs) == 1:
        return f"{name} (tau {pairs[0][0]:g} s, s {pairs[0][1]:g}{dead})"
    return f"{name} (" + ", ".join(f"({t:g} s, {s:g})" for t, s in pairs) + f"{dead})"


def _write(res: dict, out: Path, sched: dict) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t = res["t"]
    np.savetxt(out / "error.csv", np.column_stack([t, res["err"], res["paper"], res["exact"]]), delimiter=",",
               header="t_s,error_norm,paper_bound,exact_bound", comments="")
    fig, ax = plt.subplots(figsize=(9, 5), constrained_layout=True)
    if np.any(res["paper"] > 0):      # the paper's envelope exists for its LMI gains only
        ax.semilogy(t, res["paper"], color="tab:orange", lw=1.6,
                    label="paper's bound  $\\alpha\\,\\sum_i z_i$ (claimed)")
    noisy = res.get("noise", 0.0) > 0
    ax.semilogy(t, res["exact"], color="tab:green", lw=1.6, ls="--",
                label="exact bound, rounding included" + (" (noise-free: no guarantee with noise)" if noisy else ""))
    ax.semilogy(t, res["err"], color="tab:blue", lw=1.4, label="$\\|\\hat x - x\\|$ (published estimate vs. truth)")
    # the active channel: shade channel 2's residence intervals
    taus, ss = sched["schedule.tau"], sched["schedule.s"]
    tt, k = 0.0, 0
    while tt < t[-1]:
        tau, s_ = taus[k % len(taus)], ss[k % len(ss)]
        ax.axvspan(tt + s_ * tau, tt + tau, color="0.9", lw=0, zorder=0,
                   label=("agent 2 in view (else agent 1)" if res.get("system", "paper") == "paper"
                          else "channel 2 active (else channel 1)") if k == 0 else None)
        tt += tau
        k += 1
    tail = res["err"][t >= t[-1] - 5.0]
    floor = float(np.median(tail))
    if noisy and res["exact"][-1] < floor / 3:      # only noise explains an error above the noise-free bound
        ax.axhline(floor, color="tab:blue", lw=0.8, ls=":")
        ax.annotate(f"error floor ~{floor:.1e}: measurement noise {res['noise']:g}",
                    xy=(t[-1], floor), xytext=(-6, 6), textcoords="offset points", ha="right", fontsize=8,
                    color="tab:blue")
    ax.set_xlabel("simulated time [s]")
    ax.set_ylabel("estimation error norm")
    # down to the smallest positive error or bound (a Kalman table reaches the rounding floor, 1e-15)
    pos = np.concatenate([res["err"], res["exact"]])
    pos = pos[np.isfinite(pos) & (pos > 0)]
    lo = max(float(pos.min()) / 3 if pos.size else 1e-8, 1e-17)
    ax.set_ylim(lo, max(np.nanmax(res["paper"]), np.nanmax(res["err"])) * 3)
    ax.set_xlim(0, t[-1])
    ax.grid(True, which="major", alpha=0.4)
    ax.grid(True, which="minor", alpha=0.12)
    ax.set_title(f"switchobs: estimator + camera_sim over DDS, {_schedule_text(res['schedule'], sched)} schedule, "
                 f"{res['rate']:g} Hz samples", fontsize=10)
    ax.text(0.99, 0.99, f"$e_0 = \\|\\hat x(0) - x(0)\\| = {res['e0']:.3g}$: the true initial error, known here "
            "because\nthe simulation knows $x(0)$; on a robot $e_0$ is a declared bound", transform=ax.transAxes,
            ha="right", va="top", fontsize=8, color="0.3")
    for k, why in enumerate(res.get("failures", [])):
        ax.text(0.01, 0.99 - 0.06 * k, f"FAILED: {why}", transform=ax.transAxes, ha="left", va="top", fontsize=8,
                color="tab:red")
    ax.legend(loc="lower left", fontsize=8.5, framealpha=0.95)
    fig.savefig(out / "error.png", dpi=130)
    plt.close(fig)


def _number(text: str, positive: bool) -> float:
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number; got {text!r}") from None
    if not (math.isfinite(v) and (v > 0 if positive else v >= 0)):
        raise argparse.ArgumentTypeError(f"must be a finite number {'> 0' if positive else '>= 0'}; got {text}")
    return v


def _positive(text: str) -> float:
    return _number(text, True)


def _nonnegative(text: str) -> float:
    return _number(text, False)


def build_parser() -> argparse.ArgumentParser:
    """The demo's options (``bash scripts/demo.sh --help``; the documentation's command reference)."""
    ap = OneLineParser(prog="switchobs-demo", description=__doc__.split("\n\n")[0])
    ap.add_argument("--schedule", choices=sorted(SCHEDULES), default="periodic")
    ap.add_argument("--duration", type=_positive, default=30.0, help="simulated seconds (> 0, default 30)")
    ap.add_argument("--time-scale", type=_positive, default=2.0, help="simulated seconds per wall second (> 0)")
    ap.add_argument("--rate", type=_positive, default=100.0, help="camera rate in Hz (> 0)")
    ap.add_argument("--init", choices=["paper", "zeros"], default="paper",
                    help="initial estimate: x(0) + 0.1 randn (paper) or zeros")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--gain-table", default="", help="gain table file (default: design at start-up, cached)")
    ap.add_argument("--gains", choices=["lmi", "kalman"], default="lmi",
                    help="gain family the estimator designs at start-up: the paper's LMI gains (default) or "
                         "offline Kalman gains at --rate (with --noise as the declared measurement noise)")
    ap.add_argument("--noise", type=_nonnegative, default=0.0, help="camera_sim's measurement noise std (m, >= 0)")
    ap.add_argument("--dead-time", type=_nonnegative, default=0.0,
                    help="seconds after each switch without a target pose while the camera turns (both nodes' "
                         "schedule.dead_time; default 0)")
    ap.add_argument("--system", default="paper",
                    help="the system both nodes run: a scenario or a system YAML with an inputs: section (e.g. "
                         "config/cart_pair.yaml; default: the paper's camera and two agents)")
    ap.add_argument("--initial-state", type=lambda t: tuple(float(v) for v in t.split(",")), default=None,
                    help="camera_sim's true x(0), comma-separated (default: the paper's scene; needed for another "
                         "system)")
    ap.add_argument("--out", default="out/demo", help="folder for error.png, error.csv and the node logs")
    return ap


def main(argv=None) -> int:
    a = build_parser().parse_args(argv)
    try:
        extra = {}
        if a.gains == "kalman":
            extra = {"gain_family": "kalman", "rate": float(a.rate)}
        if a.noise > 0:
            extra["noise.measurement_std"] = float(a.noise)
        else:       # noise-free samples: every one is tested against the exact bound (consistency)
            extra["consistency.check"] = "always"
        sched = dict(SCHEDULES[a.schedule], **({"schedule.dead_time": float(a.dead_time)} if a.dead_time else {}))
        res = run(a.schedule, a.duration, a.time_scale, a.rate, a.init, a.seed, Path(a.out), a.gain_table,
                  extra_estimator=extra, noise_std=a.noise, schedule_params=sched, system=a.system,
                  initial_state=a.initial_state)
    except RuntimeError as err:
        print(f"demo: error: {err}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:      # run()'s finally has stopped the nodes
        print("demo: interrupted; the nodes are stopped", file=sys.stderr)
        return 130
    print(f"wrote {Path(a.out) / 'error.png'} and {Path(a.out) / 'error.csv'}")
    if res["failures"]:
        print(f"demo: FAILED: {'; '.join(res['failures'])}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
