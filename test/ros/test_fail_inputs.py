"""Bad input, message by message, through the estimator's input pipeline (the code the node runs
on every message; no DDS): each case is rejected and counted under its reason, nothing else
changes, nothing non-finite comes out, and the next valid sample is still answered. Then
100 000 seeded random messages on all three topics in one run, every valid one answered.

The node-level counterparts (a real estimator process over DDS) are in test_estimator_node.py
and test_fail_node.py.
"""

from __future__ import annotations

import math
from collections import Counter

import numpy as np
import pytest
from rclpy.serialization import serialize_message
from std_msgs.msg import UInt8

import msg_bridge as mb
from switchobs_ros.estimator import PARAMS
from switchobs_ros.pipeline import EstimatorPipeline

S = 1_000_000_000
MS = 1_000_000
NOW = 100_000 * S        # the node clock in these tests


@pytest.fixture(scope="module")
def cfg(paper_tables):
    c = {p.name: p.default for p in PARAMS}
    c["gain_table"] = paper_tables["periodic"]
    return c


@pytest.fixture
def pl(cfg):
    return EstimatorPipeline.from_params(cfg)


def _pose(xy, ns, frame="map"):
    return mb.xy_to_pose(xy, ns, frame)


def _pair(pl, ns, cam=(0.1, 0.2), tgt=(3.0, 1.0)):
    out = pl.on_pose("camera", _pose(cam, ns), NOW)
    out += pl.on_pose("target", _pose(tgt, ns), NOW)
    return out


def _started(pl, channel=1, t0=NOW - 10 * S):
    pl.on_channel(UInt8(data=channel))
    out = _pair(pl, t0)
    assert [e.stamp_ns for e in out] == [t0]
    return t0


def _state(pl):
    return (pl.observer.x_hat.tolist(), pl.obs_ns, dict(pl.last_ns), pl.updates, pl.channel)


def _set(msg, path, value):
    obj = msg
    *head, last = path.split(".")
    for h in head:
        obj = getattr(obj, h)
    setattr(obj, last, value)
    return msg


POSE_FIELDS = ["pose.position.x", "pose.position.y", "pose.position.z", "pose.orientation.x",
               "pose.orientation.y", "pose.orientation.z", "pose.orientation.w"]


def _check_rejected(pl, part, msg, reason):
    """``msg`` rejected for ``reason``, as a message and as the serialised bytes the node takes."""
    before = _state(pl)
    for k, form in enumerate((msg, serialize_message(msg)), 1):
        out = pl.on_pose(part, form, NOW)
        assert out == []
        assert pl.rejected[(f"{part}/pose", reason)] == k, dict(pl.rejected)
        assert sum(pl.rejected.values()) == k, dict(pl.rejected)
        assert _state(pl) == before           # a rejected message changes nothing


@pytest.mark.parametrize("part", ["camera", "target"])
@pytest.mark.parametrize("field", POSE_FIELDS)
@pytest.mark.parametrize("value", [math.nan, math.inf, -math.inf])
def test_non_finite_in_any_pose_field(pl, part, field, value):
    t0 = _started(pl)
    _check_rejected(pl, part, _set(_pose((0.0, 0.0), t0 + 10 * MS), field, value), "non_finite")
    assert [e.stamp_ns for e in _pair(pl, t0 + 20 * MS)] == [t0 + 20 * MS]   # still answered


@pytest.mark.parametrize("part", ["camera", "target"])
@pytest.mark.parametrize("field,value", [("pose.position.x", 1e300), ("pose.position.y", -1e300),
                                         ("pose.position.z", 1e300), ("pose.position.x", 1.0000001e6)])
def test_values_too_large(pl, part, field, value):
    t0 = _started(pl)
    _check_rejected(pl, part, _set(_pose((0.0, 0.0), t0 + 10 * MS), field, value), "too_large")
    out = _pair(pl, t0 + 20 * MS)
    assert [e.stamp_ns for e in out] == [t0 + 20 * MS] and np.isfinite(out[0].x_hat).all()


@pytest.mark.parametrize("part", ["camera", "target"])
@pytest.mark.parametrize("case,reason", [
    ("older", "old_stamp"), ("duplicate", "duplicate_stamp"), ("future", "future_stamp"), ("zero", "zero_stamp"),
    ("negative_sec", "bad_stamp"), ("nanosec_overflow", "bad_stamp"), ("wrong_frame", "wrong_frame"),
    ("empty_frame", "wrong_frame"),
])
def test_stamps_and_frames(pl, part, case, reason):
    t0 = _started(pl)
    msg = {
        "older": lambda: _pose((0, 0), t0 - 1 * MS),
        "duplicate": lambda: _pose((0, 0), t0),
        "future": lambda: _pose((0, 0), NOW + pl.future_ns + 1),
        "zero": lambda: _pose((0, 0), 0),
        "negative_sec": lambda: _set(_pose((0, 0), t0 + MS), "header.stamp.sec", -5),
        "nanosec_overflow": lambda: _set(_pose((0, 0), t0 + MS), "header.stamp.nanosec", 1_500_000_000),
        "wrong_frame": lambda: _pose((0, 0), t0 + MS, "odom"),
        "empty_frame": lambda: _pose((0, 0), t0 + MS, ""),
    }[case]()
    _check_rejected(pl, part, msg, reason)
    assert [e.stamp_ns for e in _pair(pl, t0 + 20 * MS)] == [t0 + 20 * MS]


@pytest.mark.parametrize("part", ["camera", "target"])
@pytest.mark.parametrize("damage, reason", [("truncated", "bad_layout"), ("wrong_endianness", "bad_layout"),
                                            ("frame_length", "bad_layout"), ("not_utf8", "wrong_frame")])
def test_malformed_serialised_pose_is_rejected(pl, part, damage, reason):
    """The node takes poses as serialised bytes (msg_bridge.parse): bytes that rclpy cannot read
    as a PoseStamped either are rejected as ``bad_layout``; bytes it reads (a frame id that is not
    UTF-8, read with its bad bytes replaced) are checked as that message (here: not the input
    frame). Counted, and nothing else changes."""
    t0 = _started(pl)
    good = serialize_message(_pose((0.0, 0.0), t0 + MS))
    bad = {"truncated": lambda: good[:-5], "wrong_endianness": lambda: b"\x00\x00" + good[2:],
           "frame_length": lambda: good[:12] + (2**31).to_bytes(4, "little") + good[16:],
           "not_utf8": lambda: good[:16] + b"\xff" + good[17:]}[damage]()
    before = _state(pl)
    assert pl.on_pose(part, bad, NOW) == []
    assert dict(pl.rejected) == {(f"{part}/pose", reason): 1} and _state(pl) == before
    assert [e.stamp_ns for e in _pair(pl, t0 + 20 * MS)] == [t0 + 20 * MS]


@pytest.mark.parametrize("as_bytes", [False, True])
def test_an_invalid_stamp_with_a_bad_field_is_counted_under_the_field(pl, as_bytes):
    """The checks run in their documented order (fields, frame, then the stamp): a pose with a NaN
    and a nanosec of 1e9 is ``non_finite``, by bytes and by message alike, never an internal error."""
    t0 = _started(pl)
    msg = _pose((0.0, 0.0), t0 + MS)
    msg.header.stamp.nanosec = 10**9
    msg.pose.position.x = math.nan
    before = _state(pl)
    assert pl.on_pose("camera", serialize_message(msg) if as_bytes else msg, NOW) == []
    assert dict(pl.rejected) == {("camera/pose", "non_finite"): 1} and _state(pl) == before


def test_future_within_tolerance_is_accepted(pl):
    _started(pl)
    s = NOW + pl.future_ns          # exactly at the tolerance: accepted
    assert [e.stamp_ns for e in _pair(pl, s)] == [s]


@pytest.mark.parametrize("value", [0, 3, 255])
def test_channel_not_configured(pl, value):
    t0 = _started(pl, channel=2)
    pl.on_channel(UInt8(data=value))
    assert pl.rejected[("camera/active_channel", "bad_channel")] == 1 and pl.channel == 2
    out = _pair(pl, t0 + 10 * MS)
    assert [e.stamp_ns for e in out] == [t0 + 10 * MS] and pl.observer.channel == 2   # channel 2 kept


@pytest.mark.parametrize("part", ["camera", "target"])
def test_pose_before_any_channel(pl, part):
    _check_rejected(pl, part, _pose((1.0, 2.0), NOW - S), "no_channel")
    assert pl.origin_ns is None and pl.updates == 0


@pytest.mark.parametrize("age_ns", [0, 5 * MS])
def test_target_older_than_last_switch(pl, age_ns):
    """Target t1 on channel 1, then the switch to channel 2, then a target stamped at or before t1
    (a late copy): it was taken while channel 1 was active, so it is stale_after_switch (not just
    old_stamp); the next target after the switch is answered on channel 2."""
    t0 = _started(pl, channel=1)
    t1 = t0 + 10 * MS
    assert [e.stamp_ns for e in _pair(pl, t1)] == [t1]
    pl.on_channel(UInt8(data=2))
    _check_rejected(pl, "target", _pose((3.0, 1.0), t1 - age_ns), "stale_after_switch")
    t2 = t1 + 10 * MS
    assert [e.stamp_ns for e in _pair(pl, t2)] == [t2] and pl.observer.channel == 2


def test_camera_pose_before_the_switch_message_is_fine(pl):
    """DDS may deliver the camera pose of tick k before the channel message of tick k (different
    topics): camera poses do not depend on the channel, the pair is answered on the new channel."""
    t0 = _started(pl, channel=1)
    t1 = t0 + 10 * MS
    assert pl.on_pose("camera", _pose((0.1, 0.2), t1), NOW) == []
    pl.on_channel(UInt8(data=2))
    out = pl.on_pose("target", _pose((3.0, 1.0), t1), NOW)
    assert [e.stamp_ns for e in out] == [t1] and pl.observer.channel == 2 and pl.partial_updates == 0
    assert sum(pl.rejected.values()) == 0


def test_exception_in_the_observer_is_caught_counted(pl, monkeypatch):
    t0 = _started(pl)

    def boom(*a, **k):
        raise RuntimeError("injected")
    monkeypatch.setattr(pl.observer, "update", boom)
    assert _pair(pl, t0 + 10 * MS) == []
    assert pl.rejected[("target/pose", "internal_error")] == 1 and "injected" in pl.last_rejection
    monkeypatch.undo()
    assert [e.stamp_ns for e in _pair(pl, t0 + 20 * MS)] == [t0 + 20 * MS]


def test_non_finite_estimate_is_never_returned(pl, monkeypatch):
    t0 = _started(pl)
    real = pl.observer.update

    def nan_update(*a, **k):
        x = real(*a, **k)
        x[3] = math.nan
        return x
    monkeypatch.setattr(pl.observer, "update", nan_update)
    assert _pair(pl, t0 + 10 * MS) == []          # not returned; the estimator resets instead
    assert pl.resets == 1 and pl.errors == 1 and pl.origin_ns is None


def test_bound_that_cannot_be_computed_is_withdrawn_not_reset(pl, monkeypatch):
    """The observer's bound can no longer be computed (its ellipsoid overflowed: ``envelope()``
    gives inf and ``bounds_withdrawn`` the reason): the good estimate is published as usual, the
    bounds are withdrawn with that reason (-1), and the estimator is not reset."""
    # these poses do not fit the model's e0 ball: the consistency test would withdraw the bounds at
    # the first sample, with its own reason (a withdrawal keeps its first reason)
    pl.screening.check = False
    t0 = _started(pl)
    assert pl.bound_valid
    obs = pl.observer
    assert obs._bound is not None
    monkeypatch.setattr(obs._bound, "withdrawn", "the rounding bound's ellipsoid overflowed (test)")
    out = _pair(pl, t0 + 10 * MS)
    assert [e.stamp_ns for e in out] == [t0 + 10 * MS] and np.isfinite(out[0].x_hat).all()
    assert out[0].envelope[-1] == -1.0 and np.isfinite(out[0].envelope).all()
    assert pl.resets == 0 and pl.nonfinite == 0 and not pl.bound_valid
    assert "overflowed (test)" in pl.bound_invalid_why
    out = _pair(pl, t0 + 20 * MS)               # and it keeps answering
    assert [e.stamp_ns for e in out] == [t0 + 20 * MS] and pl.resets == 0


def test_gap_so_long_the_step_overflows_resets_instead_of_publishing(pl):
    """A valid sample 10^4 s after the last one: the exact step of the unstable agents overflows.
    Nothing non-finite is returned; the estimator resets and answers the next sample afresh."""
    t0 = _started(pl, t0=NOW - 20_000 * S)
    far = t0 + 10_000 * S
    assert _pair(pl, far) == []
    assert pl.nonfinite == 1 and pl.resets == 1 and pl.origin_ns is None
    out = _pair(pl, far + 10 * MS)
    assert [e.stamp_ns for e in out] == [far + 10 * MS]
    np.testing.assert_array_equal(out[0].x_hat, np.zeros(12))      # the initial estimate, new origin
    assert np.isfinite(out[0].envelope).all()


# ----------------------------------------------------------------------------- fuzz
BAD_POSE = ("nan", "inf", "huge", "frame", "zero", "older", "duplicate", "future", "negative")
REASON = {"nan": "non_finite", "inf": "non_finite", "huge": "too_large", "frame": "wrong_frame",
          "zero": "zero_stamp", "older": "old_stamp", "duplicate": "duplicate_stamp", "future": "future_stamp",
          "negative": "bad_stamp"}


def _stream(n_msgs: int, seed: int, now_ns: int = NOW, clock=None):
    """A seeded random stream on all three topics whose valid messages are known.

    Valid: poses with stamps increasing over the whole stream (pairs, or a half alone whose
    partner never comes), channel values 1..2 (a switch only between ticks). Invalid: copies
    with a bad field or a stamp that is older / duplicate (relative to the last valid stamp of
    that topic), in the future, zero or negative; channel values 0 or 3..255. Yields
    (kind, part, msg, expected) with expected the stamp that must be answered (or None) or the
    rejection reason. ``clock`` (default: the constant ``now_ns``) is the receiver's clock when
    a future stamp is made.
    """
    rng = np.random.default_rng(seed)
    t = now_ns - 5000 * S
    last = {"camera": None, "target": None}
    yield "channel", None, UInt8(data=1), 1         # the first channel (a pose before it: see above)
    sent = 1
    channel, switch_ns = 1, None
    while sent < n_msgs:
        r = rng.random()
        if r < 0.04:                                             # a channel message
            v = int(rng.integers(1, 3)) if rng.random() < 0.7 else int(rng.choice([0, *range(3, 256)]))
            if 1 <= v <= 2 and v != channel:
                channel = v
                if last["target"] is not None:
                    switch_ns = last["target"]
            yield "channel", None, UInt8(data=v), (v if 1 <= v <= 2 else "bad_channel")
            sent += 1
            continue
        if r < 0.55:                                             # a valid tick: both halves or one
            t += int(rng.integers(1, 30)) * MS
            parts = ["camera", "target"] if rng.random() < 0.9 else [str(rng.choice(["camera", "target"]))]
            for part in parts:
                xy = rng.normal(0.0, 50.0, 2)
                yield "valid", part, _pose(xy, t), t
                last[part] = t
                sent += 1
            continue
        part = str(rng.choice(["camera", "target"]))            # an invalid pose
        kind = str(rng.choice(BAD_POSE))
        if kind in ("older", "duplicate") and last[part] is None:
            kind = "nan"
        ns = t + int(rng.integers(1, 5)) * MS
        msg = _pose(rng.normal(0.0, 50.0, 2), ns)
        if kind in ("nan", "inf", "huge"):
            field = str(rng.choice(POSE_FIELDS if kind != "huge" else POSE_FIELDS[:3]))
            _set(msg, field, {"nan": math.nan, "inf": -math.inf if rng.random() < 0.5 else math.inf,
                              "huge": float(rng.choice([1e300, -1e300, 1e7]))}[kind])
        elif kind == "frame":
            msg.header.frame_id = str(rng.choice(["odom", "", "MAP", "map "]))
        elif kind == "zero":
            msg.header.stamp = mb.ns_to_stamp(0)
        elif kind == "older":
            msg.header.stamp = mb.ns_to_stamp(last[part] - int(rng.integers(1, 10**9)))
        elif kind == "duplicate":
            msg.header.stamp = mb.ns_to_stamp(last[part])
        elif kind == "future":
            ahead = int(rng.integers(2 * S, 10**12))       # relative to the receiver's clock at sending
            msg.header.stamp = mb.ns_to_stamp((clock() if clock else now_ns) + ahead)
        elif kind == "negative":
            msg.header.stamp.sec = -int(rng.integers(1, 2**31))
        reason = REASON[kind]
        if part == "target" and kind in ("older", "duplicate") and switch_ns is not None \
                and mb.stamp_to_ns(msg.header.stamp) <= switch_ns:
            reason = "stale_after_switch"       # older than the last switch: the specific reason
        yield "invalid", part, msg, reason
        sent += 1


@pytest.mark.slow
def test_fuzz_100k_messages_every_valid_one_answered(pl):
    N = 100_000
    answered: list[int] = []
    expected_stamps: list[int] = []
    expected_rej: Counter = Counter()
    first_channel_seen = False
    for i, (kind, part, msg, exp) in enumerate(_stream(N, seed=6)):
        if kind == "channel":
            pl.on_channel(msg)
            if exp == "bad_channel":
                expected_rej[("camera/active_channel", "bad_channel")] += 1
            else:
                first_channel_seen = True
            continue
        out = pl.on_pose(part, serialize_message(msg) if i % 4 == 0 else msg, NOW)    # a quarter as the node takes it
        if kind == "valid":
            if not first_channel_seen:
                expected_rej[(f"{part}/pose", "no_channel")] += 1
            elif not expected_stamps or expected_stamps[-1] != exp:
                expected_stamps.append(exp)
        else:
            expected_rej[(f"{part}/pose", exp)] += 1
        for e in out:
            assert np.isfinite(e.x_hat).all() and np.isfinite(e.envelope).all()
            answered.append(e.stamp_ns)
    for e in pl.flush_all():
        answered.append(e.stamp_ns)
    assert pl.rejected[("target/pose", "stale_after_switch")] > 100      # the case occurs in the stream
    assert answered == expected_stamps            # every valid stamp, once, in order
    assert dict(pl.rejected) == dict(expected_rej)
    assert pl.errors == 0 and sum(pl.accepted.values()) > 0.5 * N
    assert len(answered) > 20_000


def test_messages_lost_before_the_node_are_counted_per_topic(pl):
    """The publishers' sequence numbers show the pose messages that never arrived (a best-effort
    transport, a subscription queue overwritten under a flood), per topic, as they already did for
    the channel: sent = accepted + rejected + lost. A restarted publisher starts a new sequence (no
    loss for its numbers before the first one seen); a second publisher on the topic is no gap in
    the first one's sequence. Diagnostics report them (`<topic> lost`, `<topic> publisher restarts`)."""
    from switchobs_ros.diagnostics import EstimatorDiagnostics, NodeState

    pl.on_channel(UInt8(data=1), seq=1)
    t0 = NOW - 10 * S
    sent = {"camera/pose": 0, "target/pose": 0}
    # 40 pairs, numbers 1..40 on each topic; the camera's 11..15 and the target's 30 never arrive
    for k in range(1, 41):
        ns = t0 + k * 10 * MS
        for part, topic in (("camera", "camera/pose"), ("target", "target/pose")):
            sent[topic] += 1
            if (topic == "camera/pose" and 11 <= k <= 15) or (topic == "target/pose" and k == 30):
                continue
            pl.on_message(topic, _pose((0.1, 0.2) if part == "camera" else (3.0, 1.0), ns), NOW, seq=k)
    assert dict(pl.loss.lost) == {"camera/pose": 5, "target/pose": 1}
    for topic, n in sent.items():
        got = pl.accepted[topic] + sum(c for (t, _), c in pl.rejected.items() if t == topic)
        assert got + pl.loss.lost[topic] == n
    # the camera publisher restarts (numbers from 1 again, its first 3 never seen): a new sequence, no loss;
    # a second target publisher (numbers 1, 2, 3) interleaved with the first (41, 42, 43): no loss either
    for k in range(1, 4):
        ns = t0 + (40 + k) * 10 * MS
        pl.on_message("camera/pose", _pose((0.1, 0.2), ns), NOW, seq=3 + k)
        pl.on_message("target/pose", _pose((3.0, 1.0), ns), NOW, seq=40 + k)
        pl.on_message("target/pose", _pose((3.0, 1.0), ns + 5 * MS), NOW, seq=k)
    assert dict(pl.loss.lost) == {"camera/pose": 5, "target/pose": 1}
    assert dict(pl.loss.restarts) == {"camera/pose": 1, "target/pose": 1}
    diag = EstimatorDiagnostics("/estimator", pl, NOW - S)
    arr = diag.array(type("T", (), {"nanoseconds": NOW, "to_msg": lambda self: mb.ns_to_stamp(NOW)})(),
                     NodeState(0, 0, "", 1.0, None, 0))
    vals = {kv.key: kv.value for s in arr.status for kv in s.values}
    inputs = next(s for s in arr.status if s.name.endswith("inputs"))
    assert vals["camera/pose lost"] == "5" and vals["target/pose lost"] == "1"
    assert vals["camera/active_channel lost"] == "0"
    assert vals["camera/pose publisher restarts"] == "1" and vals["target/pose publisher restarts"] == "1"
    assert "6 lost in the last period" in inputs.message and inputs.level == inputs.WARN


def test_input_covariances_are_not_used_as_the_docs_say(cfg, tmp_path):
    """PoseWithCovarianceStamped covariances (NaN, negative, asymmetric) were ignored while the
    tutorial said they are read. They are not used, whatever they hold (the noise model is the
    system's): the estimates equal those from zero covariances, bit for bit, and the tutorial
    says so."""
    from pathlib import Path

    import yaml
    from geometry_msgs.msg import PoseWithCovarianceStamped

    spec = tmp_path / "inputs.yaml"
    spec.write_text(yaml.safe_dump({"inputs": {"channel_topic": "camera/active_channel", "sources": [
        {"topic": "camera/pose", "type": "geometry_msgs/PoseWithCovarianceStamped",
         "fields": ["pose.pose.position.x", "pose.pose.position.y"], "rows": ["camera.p_x", "camera.p_y"]},
        {"topic": "target/pose", "type": "geometry_msgs/PoseWithCovarianceStamped",
         "fields": ["pose.pose.position.x", "pose.pose.position.y"], "rows": [2, 3]}]}}))

    def msg(xy, ns, cov):
        m = PoseWithCovarianceStamped()
        m.header.stamp = mb.ns_to_stamp(ns)
        m.header.frame_id = "map"
        m.pose.pose.position.x, m.pose.pose.position.y = xy
        m.pose.pose.orientation.w = 1.0
        m.pose.covariance = cov
        return m

    bad = np.arange(36.0) - 20.0                 # negative and asymmetric
    bad[7] = math.nan
    runs = []
    for cov in (np.zeros(36), bad):
        pl = EstimatorPipeline.from_params({**cfg, "inputs": str(spec)})
        pl.on_channel(UInt8(data=1))
        out = []
        for k in range(30):
            ns = NOW - 10 * S + k * 10 * MS
            out += pl.on_message("camera/pose", msg((0.1, 0.2 + k * 1e-3), ns, cov), NOW)
            out += pl.on_message("target/pose", msg((3.0, 1.0), ns, cov), NOW)
        assert len(out) == 30 and not pl.rejected
        runs.append(np.array([e.x_hat for e in out]))
    assert np.array_equal(runs[0], runs[1])
    doc = " ".join((Path(__file__).resolve().parents[2] / "docs" / "tutorials" / "own-system.md").read_text().split())
    assert "covariance is read" not in doc and "A message's covariance is not used, whatever it holds" in doc
