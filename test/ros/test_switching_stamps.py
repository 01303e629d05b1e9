"""Attribution by stamps (switchobs_msgs/ActiveChannel, switchobs_ros.switching), pairing and
clocks within the declared clock tolerance: the pipeline, no DDS. The source timestamps below
come from a channel publisher whose clock runs 40 ms behind the target's: attribution never
compares them with the samples' stamps."""

from __future__ import annotations

import pytest

import msg_bridge as mb
from msg_bridge.typed import active_channel
from switchobs_ros.estimator import PARAMS
from switchobs_ros.pipeline import EstimatorPipeline

S = 1_000_000_000
MS = 1_000_000
NOW = 100_000 * S


def _pipe(paper_tables, tolerance_ms, **params):
    c = {p.name: p.default for p in PARAMS}
    # e0 covers the scene: the consistency test (on whenever a bound is published) holds the samples to it
    c.update(gain_table=paper_tables["periodic"], clock_tolerance_ms=tolerance_ms, e0=20.0, **params)
    return EstimatorPipeline.from_params(c)


def _pose(xy, ns):
    return mb.xy_to_pose(xy, ns, "map")


def _tick(pl, t, target, now_mono, src, camera_ns=None):
    out = pl.on_pose("camera", _pose((0.0, 0.0), t if camera_ns is None else camera_ns), t + 2 * MS, now_mono, src)
    return out + pl.on_pose("target", _pose(target, t), t + 2 * MS, now_mono, src + 1)


@pytest.fixture
def exact(paper_tables):
    return _pipe(paper_tables, 0.0)


def test_first_pose_of_a_new_channel_before_its_switching_message(exact):
    """Channel 1 for its 1.2 s, t0 its last tick (beyond the horizon: it waits); the target pose of
    channel 2's first tick arrives before the switching message (stamped at that tick): it waits,
    then is read as channel 2 by its stamp, although the channel message's source timestamp
    (another clock, 40 ms behind) is older than the pose's."""
    pl = exact
    t0 = NOW - 10 * S
    src_cam = 1_000 * S                 # the channel publisher's clock
    src_tgt = src_cam + 40 * MS         # the target publisher's, 40 ms ahead
    pl.on_channel(active_channel(1, t0 - 1190 * MS), src_ns=src_cam, seq=1)     # 1.2 s residence ending
    out = _tick(pl, t0, (3.0, 1.0), 0.0, src_tgt)
    t1 = t0 + 10 * MS
    out += _tick(pl, t1, (-2.0, 2.0), 0.001, src_tgt + 10 * MS)
    assert out == []                                 # no later switching instant yet: both wait
    out = pl.on_channel(active_channel(2, t1), src_ns=src_cam + 10 * MS, now_mono=0.002, seq=2)
    # t0 is before the new instant, t1 within the new channel's horizon: both certain now
    assert [(e.stamp_ns, e.channel) for e in out] == [(t0, 1), (t1, 2)]
    assert sum(pl.rejected.values()) == 0 and pl.late_channel == 0 and pl.bound_valid


def test_a_repeated_switching_message_lost_is_harmless(exact):
    """camera_sim repeats the switching message every tick: a gap in the sequence numbers between
    two messages of the same instant loses nothing."""
    pl = exact
    t0 = NOW - 10 * S
    pl.on_channel(active_channel(1, t0), src_ns=S, seq=1)
    pl.on_channel(active_channel(1, t0), src_ns=S + 30 * MS, seq=4)
    out = _tick(pl, t0 + 10 * MS, (3.0, 1.0), 0.0, S + 10 * MS)
    out += pl.flush_overdue(1.0, 0.2)
    assert [e.channel for e in out] == [1] and pl.lost_channel == 0 and pl.bound_valid


def test_a_sample_near_a_switching_instant_loses_its_channel_rows(paper_tables):
    """Tolerance 3 ms: a target pose stamped 2 ms before the switching instant is ambiguous; with
    the consistency test off its channel rows are dropped (counted) and the camera rows used."""
    pl = _pipe(paper_tables, 3.0)
    t0 = NOW - 10 * S
    pl.on_channel(active_channel(1, t0 - S), src_ns=S, seq=1)
    pl.on_channel(active_channel(2, t0 + 2 * MS), src_ns=S + 10 * MS, seq=2)
    out = _tick(pl, t0, (3.0, 1.0), 0.0, S + 20 * MS)
    assert [e.stamp_ns for e in out] == [t0]
    assert pl.near_switch == 1 and pl.partial_updates == 1
    assert pl.rejected[("target/pose", "ambiguous_channel")] == 1
    assert pl.bound_valid


def test_halves_within_the_tolerance_pair(paper_tables):
    """Tolerance 3 ms: the camera's half stamped 2 ms after the target's forms one sample with it,
    stamped as the target's; 5 ms apart they do not."""
    pl = _pipe(paper_tables, 3.0)
    t0 = NOW - 10 * S
    pl.on_channel(active_channel(1, t0 - S), src_ns=S, seq=1)
    out = _tick(pl, t0, (3.0, 1.0), 0.0, S, camera_ns=t0 + 2 * MS)
    out += pl.flush_overdue(1.0, 0.2)
    assert [e.stamp_ns for e in out] == [t0] and pl.partial_updates == 0 and pl.parts_used == 2
    out = _tick(pl, t0 + 10 * MS, (3.0, 1.0), 2.0, S + 10 * MS, camera_ns=t0 + 15 * MS)
    out += pl.flush_overdue(3.0, 0.2)
    assert pl.partial_updates == 2


def test_stamps_ahead_beyond_the_tolerance_withdraw_the_bounds(paper_tables):
    """A camera pose stamped 20 ms after its receive time (the node clock), tolerance 3 ms: its
    clock is proven ahead, the bounds are withdrawn naming the source and the offset; 2 ms ahead is
    within the tolerance."""
    pl = _pipe(paper_tables, 3.0)
    t0 = NOW - 10 * S
    pl.on_channel(active_channel(1, t0 - S), src_ns=S, seq=1)
    pl.on_pose("camera", _pose((0.0, 0.0), t0), t0 - 2 * MS, 0.0, S)
    assert pl.bound_valid and pl.clocks.offsets_ms()["camera/pose"] == pytest.approx(-2.0)
    pl.on_pose("camera", _pose((0.0, 0.0), t0 + 10 * MS), t0 - 10 * MS, 0.0, S)
    assert not pl.bound_valid
    assert "camera/pose's stamps are 20.000 ms ahead of the estimator's clock" in pl.bound_invalid_why
    assert pl.clocks.skewed == {"camera/pose": 20 * MS}


def test_the_tolerance_enters_the_bound(paper_tables):
    """The same samples with a clock tolerance give a larger bound (the stamp error's measurement
    error is in the sets) than with exact stamps."""
    bounds = []
    for tol in (0.0, 2.0):
        pl = _pipe(paper_tables, tol)
        t0 = NOW - 10 * S
        pl.on_channel(active_channel(1, t0 - S), src_ns=S, seq=1)
        out = []
        for k in range(20):
            out += _tick(pl, t0 + k * 10 * MS, (3.0, 1.0), k * 1.0, S + k * 10 * MS)
        out += pl.flush_overdue(100.0, 0.2)
        bounds.append(out[-1].envelope[-1])
    assert 0.0 < bounds[0] < bounds[1]


def test_within_the_horizon_a_sample_is_answered_at_once(exact):
    """Channel 1 from t0, the paper's cycle (2 s, 0.6): channel 1 is active 1.2 s, no switch before
    0.9 x 1.2 s: a sample 1 s after the instant is certain at once (no later channel message
    needed); one 1.1 s after it waits for its channel."""
    pl = exact
    assert pl.attribution.stamped.horizon == {1: int(0.9 * 1.2 * S), 2: int(0.9 * 0.8 * S)}
    t0 = NOW - 10 * S
    pl.on_channel(active_channel(1, t0), src_ns=S, seq=1)
    assert [e.stamp_ns for e in _tick(pl, t0 + S, (3.0, 1.0), 0.0, S)] == [t0 + S]
    assert _tick(pl, t0 + 1100 * MS, (3.0, 1.0), 0.1, S + 10 * MS) == []


@pytest.mark.parametrize("fraction", [1.0, 0.5])
def test_the_horizon_is_the_switch_horizon_of_the_residence(paper_tables, fraction):
    """``switch_horizon`` sets the horizon: at 1 a sample 1 ms before the end of channel 1's 1.2 s
    is certain at once; at 0.5 one at 0.7 s waits for its channel and one at 0.5 s less 1 ms does not."""
    pl = _pipe(paper_tables, 0.0, switch_horizon=fraction)
    assert pl.attribution.stamped.horizon == {1: int(fraction * 1.2 * S), 2: int(fraction * 0.8 * S)}
    t0 = NOW - 10 * S
    pl.on_channel(active_channel(1, t0), src_ns=S, seq=1)
    inside = t0 + int(fraction * 1.2 * S) - MS
    assert [e.stamp_ns for e in _tick(pl, inside, (3.0, 1.0), 0.0, S)] == [inside]
    if fraction < 1.0:
        assert _tick(pl, t0 + 700 * MS, (3.0, 1.0), 0.1, S + 10 * MS) == []


def test_a_switch_horizon_outside_zero_to_one_is_refused(paper_tables):
    from switchobs_ros.config import ConfigError
    with pytest.raises(ConfigError, match="switch_horizon"):
        _pipe(paper_tables, 0.0, switch_horizon=1.5)


def test_a_switch_sooner_than_the_schedule_withdraws_the_bounds(exact):
    """A switch 200 ms after the last (the schedule broken): the samples answered at once on the
    old channel were wrong, and the switching message that says so withdraws the bounds."""
    pl = exact
    t0 = NOW - 10 * S
    pl.on_channel(active_channel(1, t0), src_ns=S, seq=1)
    _tick(pl, t0 + 200 * MS, (3.0, 1.0), 0.0, S)
    assert pl.bound_valid
    pl.on_channel(active_channel(2, t0 + 200 * MS), src_ns=S + 200 * MS, now_mono=0.1, seq=2)
    assert not pl.bound_valid and pl.late_channel == 1
    assert "arrived after samples it governs were answered" in pl.bound_invalid_why


def test_a_recording_of_either_channel_type_gives_the_same_estimates(paper_tables, tmp_path):
    """`switchobs_bag estimate` on the same scenario recorded with the stamped channel and with
    std_msgs/UInt8 (8 s, eight switches): the same estimates, every one within its exact bound
    against the truth."""
    import numpy as np

    from switchobs_ros.bag.estimate import estimate
    from switchobs_ros.bag.generate import GenerateConfig, generate, scenario_ticks

    runs = {}
    for kind in ("switchobs_msgs/msg/ActiveChannel", "std_msgs/msg/UInt8"):
        cfg = GenerateConfig(duration=8.0, rate=50.0, channel_type=kind)
        generate(tmp_path / kind.split("/")[-1], cfg)
        c = {p.name: p.default for p in PARAMS}
        c.update(gain_table=paper_tables["periodic"], e0=5.0)
        runs[kind] = estimate(tmp_path / kind.split("/")[-1], c)
    a, b = runs.values()
    assert len(a.stamps) == len(b.stamps) == 401 and a.switches == b.switches == 8
    np.testing.assert_array_equal(a.stamps, b.stamps)
    np.testing.assert_allclose(a.x_hat, b.x_hat, rtol=0, atol=1e-12)
    truth = {s: np.asarray(m.data[2:]) for s, msgs in scenario_ticks(cfg) for t, m in msgs if t == "/sim/truth"}
    err = np.array([np.linalg.norm(x - truth[s]) for s, x in zip(a.stamps.tolist(), a.x_hat)])
    assert (err <= a.envelope[:, -1] * (1 + 1e-9)).all()


def test_a_lost_first_switching_message_leaves_only_the_end_of_the_residence_unknown(exact):
    """camera_sim repeats the switching message each tick: the first message of channel 2 lost,
    its repetition says channel 2 from t1. The samples of channel 1's residence before its horizon
    (0.9 x 1.2 s) stay attributed and the bounds valid; one after it, before t1, is unknown (its
    target pose dropped, counted as lost)."""
    pl = exact
    t0 = NOW - 10 * S
    pl.on_channel(active_channel(1, t0), src_ns=S, seq=1)
    out = _tick(pl, t0 + S, (3.0, 1.0), 0.0, S)                    # within the horizon: at once
    out += _tick(pl, t0 + 1100 * MS, (3.0, 1.0), 0.1, S + 10 * MS)   # after it: waits
    t1 = t0 + 1200 * MS
    pl.on_channel(active_channel(2, t1), src_ns=S + 20 * MS, now_mono=0.2, seq=3)   # seq 2 lost
    assert [e.stamp_ns for e in out] == [t0 + S] and pl.bound_valid
    assert pl.lost_channel == 1 and pl.rejected[("target/pose", "ambiguous_channel")] == 1


def test_a_sample_not_proven_within_the_window_is_never_guessed(exact):
    """Channel 1 from t0; a sample 1.1 s after it (beyond the horizon) whose window passes with no
    later switching message: its target pose is dropped (counted), the camera pose used alone. The
    switching message to channel 2 at that very stamp, arriving after the window, finds no answer
    on a guessed channel: the bounds stay valid."""
    pl = exact
    t0 = NOW - 10 * S
    pl.on_channel(active_channel(1, t0), src_ns=S, seq=1)
    t1 = t0 + 1100 * MS
    out = _tick(pl, t1, (3.0, 1.0), 0.0, S + 10 * MS)
    assert out == []                                     # waits for its channel
    out = pl.flush_overdue(0.06, 0.2)                    # the 50 ms window passed
    assert [e.stamp_ns for e in out] == [t1] and pl.partial_updates == 1
    assert pl.uncertain == 1 and pl.rejected[("target/pose", "ambiguous_channel")] == 1
    pl.on_channel(active_channel(2, t1), src_ns=S + 20 * MS, now_mono=0.1, seq=2)
    assert pl.bound_valid and pl.late_channel == 0


def test_a_lost_switching_message_after_proven_answers_keeps_the_bounds(exact):
    """Channel 1 from t0; samples after the horizon are proven by the repetitions sent after them
    and answered. The first message of channel 2 (seq 3) is lost and found missing at its
    repetition (seq 4): the answers were proven, the bounds stay valid; a sample sent after the
    last message ahead of the gap, stamped in it, has an unknown channel (target pose dropped)."""
    pl = exact
    t0 = NOW - 10 * S
    pl.on_channel(active_channel(1, t0), src_ns=S, seq=1)
    t1 = t0 + 1100 * MS
    out = _tick(pl, t1, (3.0, 1.0), 0.0, S + 10 * MS)
    out += pl.on_channel(active_channel(1, t0), src_ns=S + 15 * MS, now_mono=0.005, seq=2)
    assert [(e.stamp_ns, e.channel) for e in out] == [(t1, 1)] and pl.partial_updates == 0
    out = _tick(pl, t1 + 10 * MS, (3.0, 1.0), 0.01, S + 20 * MS)      # sent after seq 2: waits
    t2 = t1 + 20 * MS
    out += pl.on_channel(active_channel(2, t2), src_ns=S + 40 * MS, now_mono=0.02, seq=4)   # seq 3 lost
    assert [e.stamp_ns for e in out] == [t1 + 10 * MS]
    assert pl.lost_channel == 1 and pl.rejected[("target/pose", "ambiguous_channel")] == 1
    assert pl.bound_valid and pl.late_channel == 0
