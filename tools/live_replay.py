"""A live replay, end to end: estimator, recorder and player as separate processes over DDS.

Used by the acceptance tests and bench/bench_bag.py. The estimator runs with
``use_sim_time:=true``; ``switchobs_bag record`` records its outputs and ``/diagnostics`` with
receive times on the system clock (monotone across the passes of a looped replay, and no wait
for its own ``/clock`` match); ``switchobs_bag play`` publishes the bag with ``/clock``. Every process gets
``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`` and the caller's ``ROS_DOMAIN_ID`` (NodeProcess).
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

from tools.launch import NodeProcess, ros_args

__all__ = ["OUTPUT_TOPICS", "live_replay"]

OUTPUT_TOPICS = ("/estimator/state", "/estimator/envelope", "/estimator/camera/odom", "/estimator/agent1/odom",
                 "/estimator/agent2/odom", "/diagnostics")


def _bag_cmd() -> list[str]:
    return [sys.executable, "-m", "switchobs_ros.bag"]


def _wait_for(proc: NodeProcess, text: str, timeout: float) -> None:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if text in proc.output():
            return
        if not proc.alive():
            raise RuntimeError(f"{proc.name} exited with {proc.proc.returncode}:\n{proc.output()[-3000:]}")
        time.sleep(0.05)
    raise RuntimeError(f"{proc.name}: no '{text}' within {timeout:g} s:\n{proc.output()[-3000:]}")


def live_replay(bag: str | Path, out_bag: str | Path, workdir: str | Path, estimator_params: dict, *,
                rate: float = 1.0, loops: int = 1, play_args: tuple = (), timeout: float = 120.0,
                record_topics: tuple = OUTPUT_TOPICS) -> dict:
    """Play ``bag`` into an estimator process and record its outputs to ``out_bag``.

    Returns the wall seconds of the playback (player start to exit, without the waits) and the
    processes' logs. Raises RuntimeError with the logs if a process fails.
    """
    workdir = Path(workdir)
    workdir.mkdir(parents=True, exist_ok=True)
    params = dict(estimator_params, use_sim_time=True)
    est = rec = ply = None
    try:
        est = NodeProcess("estimator", ros_args(params=params), log=workdir / "estimator.log")
        rec = NodeProcess("record", ["record", str(out_bag), "--topics", *record_topics, "--wait-timeout", str(timeout),
                                     "--wait-publishers", "/estimator/state"],
                          cmd=_bag_cmd(), log=workdir / "record.log")
        _wait_for(rec, "recording", timeout)
        time.sleep(1.0)       # the recorder's subscriptions match the estimator's publishers
        ply = NodeProcess("play", ["play", str(bag), "--rate", str(rate), "--loops", str(loops), *play_args],
                          cmd=_bag_cmd(), log=workdir / "play.log")
        _wait_for(ply, "starting in", timeout)
        t0 = time.monotonic()
        rc = ply.wait(timeout)
        wall = time.monotonic() - t0
        if rc != 0:
            raise RuntimeError(f"play exited with {rc}:\n{ply.output()[-3000:]}\nestimator:\n{est.output()[-3000:]}")
        time.sleep(0.5)       # the last estimates reach the recorder
        rc = rec.stop(timeout=20.0)
        if rc != 0:
            raise RuntimeError(f"record exited with {rc}:\n{rec.output()[-3000:]}")
        return {"wall": wall, "play_log": ply.output(), "record_log": rec.output(), "estimator_log": est.output()}
    finally:
        for p in (ply, rec, est):
            if p is not None and p.alive():
                p.stop()
