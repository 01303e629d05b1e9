"""Clocks across computers over DDS: camera_sim's camera clock ahead of its targets'
(``stamp_offset_ms``), the stamped channel message sent after the tick's poses (the first pose of
a new channel before its channel message), the estimator with a declared ``clock_tolerance_ms``;
every published estimate checked against the published truth."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest

from tools import demo


def _run(tmp_path, paper_tables, offset_ms, tolerance_ms):
    return demo.run("periodic", duration=4.0, time_scale=1.0, init="paper", gain_table=paper_tables["periodic"],
                    quiet=True, out=tmp_path,
                    extra_camera={"stamp_offset_ms": offset_ms, "channel_last": True, "publish_clock": False},
                    extra_estimator={"clock_tolerance_ms": tolerance_ms, "use_sim_time": False})


@pytest.mark.slow
def test_an_offset_within_the_tolerance_keeps_a_valid_bound(tmp_path, paper_tables):
    """Camera clock 2 ms ahead, tolerance 3 ms, every channel message after its tick's poses: no
    published estimate above a valid bound, and a valid bound on >= 90 % of the answers after 1 s."""
    res = _run(tmp_path, paper_tables, 2.0, 3.0)
    err, exact, t = res["err"], res["exact"], res["t"]
    valid = exact > 0
    assert not (valid & (err > exact * (1 + 1e-9))).any(), float(np.max(err[valid] / exact[valid]))
    late = t >= 1.0
    assert valid[late].mean() >= 0.9, valid[late].mean()
    assert res["n_state"] >= 0.9 * res["n_truth"]          # answered (the targets' samples, paired)


@pytest.mark.slow
def test_an_offset_beyond_the_tolerance_withdraws_the_bounds(tmp_path, paper_tables):
    """Camera clock 50 ms ahead, tolerance 3 ms: the bounds are withdrawn (no valid bound is
    published after the first second) and the log names the source and the offset."""
    res = _run(tmp_path, paper_tables, 50.0, 3.0)
    log = _withdrawn(res, tmp_path)
    assert "clock offset: camera/pose's stamps are " in log and "ms ahead of the estimator's clock" in log, log[-2000:]
    ms = float(log.split("camera/pose's stamps are ")[1].split(" ms")[0])
    assert 3.0 < ms <= 50.0, ms        # beyond the tolerance, at most the offset (less that message's latency)


def _withdrawn(res: dict, out: Path) -> str:
    """Assert that no published estimate is above a valid bound and that no bound is valid after the
    first second; return the estimator's log."""
    valid = res["exact"] > 0
    assert not (valid & (res["err"] > res["exact"] * (1 + 1e-9))).any()
    assert not valid[res["t"] >= 1.0].any()
    return (out / "estimator.log").read_text()


def _faketime() -> Path | None:
    """libfaketime's preload library (the ``libfaketime`` wheel of requirements.txt), or None."""
    spec = importlib.util.find_spec("libfaketime")
    if spec is None or not spec.submodule_search_locations:
        return None
    so = Path(spec.submodule_search_locations[0]) / "vendor" / "libfaketime" / "src" / "libfaketime.so.1"
    return so if so.exists() else None


@pytest.mark.slow
def test_a_computer_clock_ahead_is_caught_with_the_default_zero_tolerance(tmp_path, paper_tables):
    """camera_sim on a "computer" whose whole clock runs 50 ms ahead (libfaketime preloaded: its
    header stamps and its middleware's source timestamps alike), the estimator with the shipped
    zero tolerance (one computer declared): the middleware's timestamps prove the offset, the bounds
    are withdrawn naming it, and no published estimate is above a valid bound."""
    so = _faketime()
    if so is None:
        pytest.skip("libfaketime (requirements.txt) is not installed")
    env = {"LD_PRELOAD": str(so), "FAKETIME": "+0.05", "FAKETIME_DONT_FAKE_MONOTONIC": "1"}
    res = demo.run("periodic", duration=4.0, time_scale=1.0, init="paper", gain_table=paper_tables["periodic"],
                   quiet=True, out=tmp_path, extra_camera={"publish_clock": False},
                   extra_estimator={"use_sim_time": False}, camera_env=env)
    log = _withdrawn(res, tmp_path)
    assert "(DDS source timestamp)'s stamps are " in log and "one computer declared" in log, log[-2000:]
    ms = float(log.split("(DDS source timestamp)'s stamps are ")[1].split(" ms")[0])
    assert 1.0 < ms <= 50.0, ms
