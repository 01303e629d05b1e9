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

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import rclpy

from switchobs_ros.core_config import DEFAULT_X0
from tools.domain import claim_domain
from tools.launch import Collector, NodeProcess, ros_args

SCHEDULES = {
    "periodic": {"schedule.mode": "periodic", "schedule.tau": [2.0], "schedule.s": [0.6]},
    "sequence": {"schedule.mode": "sequence", "schedule.tau": [4.0, 3.0, 3.0, 2.0],
                 "schedule.s": [0.5, 0.6, 0.6, 0.4]},
}


def run(schedule: str = "periodic", duration: float = 30.0, time_scale: float = 2.0, rate: float = 100.0,
        init: str = "paper", seed: int = 0, out: Path | None = None, gain_table: str = "",
        quiet: bool = False, extra_estimator: dict | None = None, noise_std: float = 0.0) -> dict:
    """Run the demo; return the collected series (stamps in s from the first tick)."""
    import os

    lease = None
    if "ROS_DOMAIN_ID" not in os.environ or os.environ.get("SWITCHOBS_CLAIM_DOMAIN", "1") == "1":
        lease = claim_domain()
        os.environ["ROS_DOMAIN_ID"] = str(lease.domain_id)
    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    out = Path(out) if out else None
    if out:
        out.mkdir(parents=True, exist_ok=True)
    x0 = np.array(DEFAULT_X0)
    if init == "paper":
        xhat0 = x0 + 0.1 * np.random.default_rng(seed).standard_normal(x0.size)
    else:
        xhat0 = np.zeros_like(x0)
    e0 = float(np.linalg.norm(xhat0 - x0))
    sched = SCHEDULES[schedule]
    est_params = dict(sched, initial_estimate=list(map(float, xhat0)), e0=e0, use_sim_time=True,
                      gain_table=gain_table)
    est_params.update(extra_estimator or {})
    cam_params = dict(sched, rate=rate, duration=duration, publish_clock=True, time_scale=time_scale,
                      wait_for_subscribers=1, wait_for_truth_subscribers=1, seed=seed, noise_std=float(noise_std))
    rclpy.init()
    node = Collector(["/estimator/state", "/estimator/envelope", "/sim/truth"], name="switchobs_demo")
    est = cam = None
    logs = out or Path(tempfile.mkdtemp(prefix="switchobs_demo_"))
    try:
        est = NodeProcess("estimator", ros_args(params=est_params), log=logs / "estimator.log")
        deadline = time.monotonic() + 120
        while not node.matched(["/estimator/state"]):       # the estimator is up (design at start-up may take a while)
            rclpy.spin_once(node, timeout_sec=0.1)
            if not est.alive():
                raise RuntimeError(f"estimator exited with {est.proc.returncode}:\n{est.output()}")
            if time.monotonic() > deadline:
                raise RuntimeError("estimator did not come up within 120 s")
        cam = NodeProcess("camera_sim", ros_args(params=cam_params), log=logs / "camera_sim.log")
        t_wall = time.monotonic()
        while cam.alive():
            rclpy.spin_once(node, timeout_sec=0.05)
        t_end = time.monotonic() + 1.0
        while time.monotonic() < t_end:  # the last answers
            rclpy.spin_once(node, timeout_sec=0.05)
        wall = time.monotonic() - t_wall
        if cam.proc.returncode != 0:
            raise RuntimeError(f"camera_sim exited with {cam.proc.returncode}:\n{cam.output()}")
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
               noise=float(noise_std))
    if not quiet:
        _report(res, sched)
    if out:
        _write(res, out, sched)
    return res


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


def _cycle_ends(sched: dict, t_end: float) -> list[float]:
    taus = sched["schedule.tau"]
    out, t, k = [], 0.0, 0
    while True:
        t += taus[k % len(taus)]
        if t > t_end + 1e-9:
            return out
        out.append(t)
        k += 1


def _report(res: dict, sched: dict) -> None:
    t, err = res["t"], res["err"]
    print(f"switchobs demo: schedule {res['schedule']}, {res['duration']:g} s simulated in {res['wall']:.1f} s "
          f"wall ({res['rate']:g} Hz); {res['n_state']} estimates for {res['n_truth']} truth samples")
    print(f"initial error ||x_hat(0) - x(0)|| = {res['e0']:.4f}")
    if res.get("noise", 0.0) > 0:
        print(f"measurement noise std {res['noise']:g}: the exact bound assumes noise-free samples, so it is "
              "printed for reference, not as a guarantee")
    print(f"{'cycle':>5} {'t [s]':>7} {'||x_hat - x||':>14} {'relative':>10} {'paper bound':>12} {'exact bound':>12}")
    for k, te in enumerate(_cycle_ends(sched, t[-1])):
        i = min(np.searchsorted(t, te - 1e-9), len(t) - 1)
        print(f"{k + 1:>5} {t[i]:>7.2f} {err[i]:>14.3e} {err[i] / res['e0']:>10.2e} "
              + (f"{res['paper'][i]:>12.3e}" if res['paper'][i] > 0 else f"{'n/a':>12}") + f" {res['exact'][i]:>12.3e}")
    print(f"final: t = {t[-1]:.2f} s, ||x_hat - x|| = {err[-1]:.3e} ({err[-1] / res['e0']:.2e} of the initial error)")


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
                   label="agent 2 in view (else agent 1)" if k == 0 else None)
        tt += tau
        k += 1
    tail = res["err"][t >= t[-1] - 5.0]
    floor = float(np.median(tail))
    if res["exact"][-1] < floor / 3:
        ax.axhline(floor, color="tab:blue", lw=0.8, ls=":")
        why = (f"measurement noise {res['noise']:g}" if noisy else
               f"zero-order hold of {res['rate']:g} Hz samples of moving bodies")
        ax.annotate(f"error floor ~{floor:.1e}: {why}",
                    xy=(t[-1], floor), xytext=(-6, 6), textcoords="offset points", ha="right", fontsize=8,
                    color="tab:blue")
    ax.set_xlabel("simulated time [s]")
    ax.set_ylabel("estimation error norm")
    lo = max(min(np.nanmin(res["err"]), np.nanmin(res["exact"])) / 3, 1e-8)
    ax.set_ylim(lo, max(np.nanmax(res["paper"]), np.nanmax(res["err"])) * 3)
    ax.set_xlim(0, t[-1])
    ax.grid(True, which="major", alpha=0.4)
    ax.grid(True, which="minor", alpha=0.12)
    ax.set_title(f"switchobs: estimator + camera_sim over DDS, {res['schedule']} schedule, "
                 f"{res['rate']:g} Hz samples", fontsize=11)
    ax.legend(loc="lower left", fontsize=8.5, framealpha=0.95)
    fig.savefig(out / "error.png", dpi=130)
    plt.close(fig)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="switchobs-demo", description=__doc__.split("\n\n")[0])
    ap.add_argument("--schedule", choices=sorted(SCHEDULES), default="periodic")
    ap.add_argument("--duration", type=float, default=30.0, help="simulated seconds (default 30)")
    ap.add_argument("--time-scale", type=float, default=2.0, help="simulated seconds per wall second")
    ap.add_argument("--rate", type=float, default=100.0, help="camera rate in Hz")
    ap.add_argument("--init", choices=["paper", "zeros"], default="paper",
                    help="initial estimate: x(0) + 0.1 randn (paper) or zeros")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--gain-table", default="", help="gain table file (default: design at start-up, cached)")
    ap.add_argument("--gains", choices=["lmi", "kalman"], default="lmi",
                    help="gain family the estimator designs at start-up: the paper's LMI gains (default) or "
                         "offline Kalman gains at --rate (with --noise as the declared measurement noise)")
    ap.add_argument("--noise", type=float, default=0.0, help="camera_sim's measurement noise std (m)")
    ap.add_argument("--out", default="out/demo", help="folder for error.png, error.csv and the node logs")
    a = ap.parse_args(argv)
    try:
        extra = {}
        if a.gains == "kalman":
            extra = {"gain_family": "kalman", "rate": float(a.rate)}
        if a.noise > 0:
            extra["noise.measurement_std"] = float(a.noise)
        run(a.schedule, a.duration, a.time_scale, a.rate, a.init, a.seed, Path(a.out), a.gain_table,
            extra_estimator=extra, noise_std=a.noise)
    except RuntimeError as err:
        print(f"demo: error: {err}", file=sys.stderr)
        return 1
    print(f"wrote {Path(a.out) / 'error.png'} and {Path(a.out) / 'error.csv'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
