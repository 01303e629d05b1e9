"""Attribution by the publisher's source timestamps, never by arrival order (the pipeline, no DDS;
the load test at the end runs the demo over DDS beside two busy loops).

camera_sim sends, per tick, the channel, then the camera pose, then the target pose; DDS and the
executor may hand them to the estimator in another order. The source timestamps say the order
they were sent in."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from std_msgs.msg import UInt8

import msg_bridge as mb
from switchobs_ros.estimator import PARAMS
from switchobs_ros.pipeline import EstimatorPipeline

S = 1_000_000_000
MS = 1_000_000
NOW = 100_000 * S
REPO = Path(__file__).resolve().parents[2]


@pytest.fixture
def pl(paper_tables):
    c = {p.name: p.default for p in PARAMS}
    c["gain_table"] = paper_tables["periodic"]
    return EstimatorPipeline.from_params(c)


def _pose(xy, ns):
    return mb.xy_to_pose(xy, ns, "map")


def test_channel_delivered_after_the_poses_it_governs(pl):
    """Tick k on channel 1, then the switch: tick k+1's channel message (channel 2) is delivered
    after tick k+1's poses. The poses wait (reorder window) and are answered on channel 2 once the
    channel message arrives; nothing is rejected."""
    src = 1_000 * S                              # the publisher's clock
    t0 = NOW - 10 * S
    assert pl.on_channel(UInt8(data=1), src_ns=src) == []
    assert pl.on_pose("camera", _pose((0.0, 0.0), t0), NOW, 0.0, src + 1) == []
    out = pl.on_pose("target", _pose((3.0, 1.0), t0), NOW, 0.0, src + 2)
    assert out == []                             # not certain yet: a channel message may still come
    # tick 1: channel 2 sent first, delivered last
    t1 = t0 + 10 * MS
    assert pl.on_pose("camera", _pose((0.0, 0.0), t1), NOW, 0.001, src + 10 * MS + 1) == []
    assert pl.on_pose("target", _pose((-2.0, 2.0), t1), NOW, 0.001, src + 10 * MS + 2) == []
    out = pl.on_channel(UInt8(data=2), src_ns=src + 10 * MS, now_mono=0.002)
    # the channel-2 message (sent after tick 0) makes tick 0 certain: channel 1
    assert [e.stamp_ns for e in out] == [t0] and pl.observer.channel == 1
    out = pl.on_channel(UInt8(data=2), src_ns=src + 20 * MS, now_mono=0.003)
    assert [e.stamp_ns for e in out] == [t1] and pl.observer.channel == 2
    assert sum(pl.rejected.values()) == 0 and pl.late_channel == 0 and pl.bound_valid


def test_window_decides_when_no_channel_message_follows(pl):
    """A channel published only on change: the last sample waits the reorder window, then takes
    the latest channel sent before it."""
    src = 1_000 * S
    t0 = NOW - 10 * S
    pl.on_channel(UInt8(data=2), src_ns=src)
    pl.on_pose("camera", _pose((0.0, 0.0), t0), NOW, 10.0, src + 1)
    assert pl.on_pose("target", _pose((-2.0, 2.0), t0), NOW, 10.0, src + 2) == []
    assert pl.flush_overdue(10.0 + pl.window_ns * 1e-9 / 2, 0.2) == []
    out = pl.flush_overdue(10.0 + pl.window_ns * 1e-9 * 1.01, 0.2)
    assert [e.stamp_ns for e in out] == [t0] and pl.observer.channel == 2


def test_late_channel_message_withdraws_the_bounds(pl):
    """A channel message that arrives after the window, for samples already answered on another
    channel: the answers may have been wrong, so the bounds are withdrawn, with the reason."""
    src = 1_000 * S
    t0 = NOW - 10 * S
    pl.on_channel(UInt8(data=1), src_ns=src)
    pl.on_pose("camera", _pose((0.0, 0.0), t0), NOW, 0.0, src + 5)
    pl.on_pose("target", _pose((3.0, 1.0), t0), NOW, 0.0, src + 6)
    assert len(pl.flush_overdue(1.0, 0.2)) == 1 and pl.bound_valid
    pl.on_channel(UInt8(data=2), src_ns=src + 3, now_mono=1.0)     # sent before the sample, delivered now
    assert pl.late_channel == 1 and not pl.bound_valid and "reorder_window" in pl.bound_invalid_why


def test_pose_sent_before_any_channel_is_no_channel(pl):
    src = 1_000 * S
    t0 = NOW - 10 * S
    pl.on_pose("camera", _pose((0.0, 0.0), t0), NOW, 0.0, src)
    pl.on_pose("target", _pose((3.0, 1.0), t0), NOW, 0.0, src + 1)
    assert pl.on_channel(UInt8(data=1), src_ns=src + 2, now_mono=0.001) == []
    assert pl.rejected[("target/pose", "no_channel")] == 1 and pl.updates == 0


@pytest.mark.slow
def test_demo_under_load_publishes_no_false_bound(tmp_path):
    """The demo (estimator + camera_sim over DDS, noise-free, time_scale 4) beside two busy-loop
    processes: it exits 0, which it does only if no published estimate is above the published
    exact bound and the final error is below 1e-4 of the initial one (tools/demo.py verdict)."""
    busy = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(2)]
    try:
        env = dict(os.environ, SWITCHOBS_CLAIM_DOMAIN="0")      # the test session's domain
        r = subprocess.run([sys.executable, "-m", "tools.demo", "--time-scale", "4", "--duration", "30",
                            "--out", str(tmp_path)], env=env, capture_output=True, text=True, timeout=300, cwd=REPO)
    finally:
        for b in busy:
            b.kill()
            b.wait()
    assert r.returncode == 0, r.stdout[-2000:] + r.stderr[-2000:]
    data = np.loadtxt(tmp_path / "error.csv", delimiter=",", skiprows=1)
    t, err, exact = data[:, 0], data[:, 1], data[:, 3]
    # best-effort sensor topics: a loaded machine drops some samples in DDS (2246 of 3001 answered with
    # two busy loops and three test runs beside it); no published bound is false. A bound may be
    # withdrawn (-1: a channel message delayed past the reorder window, honestly reported)
    valid = exact > 0
    assert t.size > 1500 and valid.any() and not (err[valid] > exact[valid]).any()
