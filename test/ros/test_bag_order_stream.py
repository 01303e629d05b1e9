"""The recording's order computed as it is read (``switchobs_ros.bag.order_stream``) is
``order_messages``' order, with the same unordered parts and unproven ties, or it says it cannot
be (``BeyondWindow``) and ``switchobs_bag estimate`` orders the whole recording: the output bag and
CSV are those of the whole recording's order either way. The bag is read by log time
chunk by chunk as ``BagIn.messages`` sorts it whole."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from rclpy.serialization import serialize_message
from std_msgs.msg import Float64MultiArray

from switchobs_ros.bag.estimate import estimate, estimator_params
from switchobs_ros.bag.generate import GenerateConfig, generate
from switchobs_ros.bag.io import BagError, BagIn, BagOut, deserialize, msg_class
from switchobs_ros.bag.order import evidence, order_messages
from switchobs_ros.bag.order_stream import BeyondWindow, StreamCounts, stream_order

S = 1_000_000_000
TICK = 10            # a tick of the synthetic recordings (ns: any unit does)


@st.composite
def recordings(draw):
    """A synthetic recording: per tick a channel message (sometimes; a value 1..3 or an invalid one),
    a camera pose (shared), two target poses (channel-dependent), a command (sometimes); each message
    logged after its stamp by a delay drawn per message (mostly none, some late by up to 40 ticks),
    log times coarsened to groups of ``g`` ticks (ties), written in an order shuffled within
    neighbourhoods (the file's order), stamps sometimes missing, duplicated, zero or in the future."""
    ticks = draw(st.integers(5, 40))
    g = draw(st.sampled_from([1, 1, 3, 7]))
    msgs = []           # (topic, stamp, dependent, channel, is_channel, nominal log)
    for k in range(ticks):
        t = (k + 1) * TICK
        if draw(st.booleans()):
            c = draw(st.sampled_from([1, 1, 2, 3, None]))
            msgs.append(("ch", None, False, c, True, t))
        msgs.append(("cam", t, False, None, False, t))
        for topic in ("t1", "t2"):
            msgs.append((topic, t, True, None, False, t))
        if draw(st.integers(0, 4)) == 0:
            msgs.append(("u", t, False, None, False, t))
    out = []
    for topic, stamp, dep, chan, is_ch, t in msgs:
        delay = draw(st.sampled_from([0, 0, 0, 0, 1, 2, 5, 15, 40])) if stamp is not None else 0
        log = ((t + delay) // (g * TICK)) * (g * TICK) if g > 1 else t + delay
        odd = draw(st.integers(0, 19)) if stamp is not None else 9
        if odd == 0:
            stamp = None
        elif odd == 1:
            stamp = 0
        elif odd == 2:
            stamp = t + 1000 * TICK            # beyond the future tolerance
        elif odd == 3:
            stamp = max(TICK, t - 3 * TICK)     # not newer than its topic's last
        out.append([topic, stamp, dep, chan, is_ch, log])
    # the file's order: the nominal order with some messages moved a few places
    order = list(range(len(out)))
    for _ in range(draw(st.integers(0, 6))):
        i = draw(st.integers(0, len(order) - 1))
        j = min(len(order) - 1, i + draw(st.integers(1, 4)))
        order[i], order[j] = order[j], order[i]
    return [out[i] for i in order]


def _whole(rec, future):
    topics = [r[0] for r in rec]
    log = [r[5] for r in rec]
    stamp = [r[1] for r in rec]
    ev = evidence(topics, log, stamp, future)
    return order_messages(log, stamp, ev, [r[2] for r in rec], [r[3] for r in rec], [r[4] for r in rec])


def _streamed(rec, future, window):
    seq = sorted(range(len(rec)), key=lambda i: rec[i][5])          # log order, ties in the file's order
    counts = StreamCounts()
    got = list(stream_order(((rec[i][5], rec[i][0], rec[i][1], rec[i][2], rec[i][3], rec[i][4], i) for i in seq),
                            future, counts, window))
    return got, counts


@settings(max_examples=400, deadline=None)
@given(rec=recordings(), window=st.sampled_from([0, 1, 5, 20, 60, 10**9]),
       future=st.sampled_from([0, TICK, 30 * TICK]))
def test_streamed_order_is_the_whole_recordings_or_refused(rec, window, future):
    """Property: on recordings with ties, late messages, a shuffled file order and odd stamps, the
    streamed order is order_messages' (the order, the unordered parts, the unproven ties) or
    BeyondWindow is raised; a window longer than the recording is never refused."""
    whole = _whole(rec, future)
    try:
        got, counts = _streamed(rec, future, window)
    except BeyondWindow:
        assert window < 10**9
        return
    assert [i for i, _ in got] == whole.order
    assert {i for i, u in got if u} == set(whole.unordered)
    assert counts.unordered == len(whole.unordered) and counts.unproven == whole.unproven


def test_a_message_later_than_the_window_is_refused_not_guessed():
    """A target pose logged 50 ticks after its stamp, after a change of the channel: with a window of
    10 ticks the stream refuses (the order needs the late message), with 100 it orders as the whole
    recording does (the targets between the late stamp and the camera's are unordered)."""
    rec = []
    for k in range(1, 80):
        t = k * TICK
        if k == 30:
            rec.append(["ch", None, False, 2, True, t])
        rec.append(["cam", t, False, None, False, t])
        if k != 20:
            rec.append(["t1", t, True, None, False, t])
    rec.append(["t2", 20 * TICK, True, None, False, 70 * TICK])       # sent at tick 20, logged at 70
    rec.sort(key=lambda r: r[5])
    whole = _whole(rec, 0)
    assert len(whole.unordered) >= 10
    with pytest.raises(BeyondWindow):
        _streamed(rec, 0, 10 * TICK)
    got, counts = _streamed(rec, 0, 100 * TICK)
    assert [i for i, _ in got] == whole.order and {i for i, u in got if u} == set(whole.unordered)


@pytest.mark.parametrize("storage", ["mcap", "sqlite3"])
def test_log_order_reads_by_log_time_as_messages_sorts(tmp_path, storage):
    """BagIn.log_order (chunk by chunk) gives the messages of BagIn.messages (read whole, sorted by
    log time, ties in the file's order), over several chunks with log times that go back, across
    chunks, and tie."""
    rng = np.random.default_rng(7)
    with BagOut(tmp_path / "b", storage) as out:
        for t in ("/a", "/b"):
            out.add(t, "std_msgs/msg/Float64MultiArray")
        for k in range(600):
            log = 1_000_000 * (k // 3) - int(rng.choice([0, 0, 0, 5_000_000, 90_000_000]))
            data = rng.standard_normal(int(rng.integers(1, 2000))).tolist()
            out.write(("/a", "/b")[k % 2], max(log, 1), serialize_message(Float64MultiArray(data=data)))
    with BagIn(tmp_path / "b") as b:
        whole = [(m.topic, m.log_ns, m.data) for m in b.messages()]
        streamed = [(m.topic, m.log_ns, m.data) for m in b.log_order()]
        in_file = [m.log_ns for m in b.messages(order="file")]
    assert streamed == whole and len(whole) == 600 and in_file != sorted(in_file)


@pytest.fixture(scope="module")
def clean(tmp_path_factory):
    d = tmp_path_factory.mktemp("order_stream")
    generate(d / "clean", GenerateConfig(duration=4.0, noise_std=0.01, seed=2), "mcap")
    return d


def _messages(path) -> list:
    """(topic, log time, message) in file order."""
    with BagIn(path) as b:
        return [(m.topic, m.log_ns, deserialize(m, msg_class(m.type))) for m in b.messages(order="file")]


def _rewrite(src, dst, log_of, storage="mcap"):
    with BagIn(src) as b:
        msgs, topics = b.messages(order="file"), dict(b.topics)
    with BagOut(dst, storage) as out:
        for t, ty in topics.items():
            out.add(t, ty)
        for m in msgs:
            out.write(m.topic, log_of(m), m.data)
    return dst


def _late(m):        # target poses of 2.15-2.2 s logged at 2.205 s, after the switch at 2.2 s (test_bag_order)
    return 2_205_000_000 if m.topic == "/target/pose" and 2_150_000_000 <= m.log_ns <= 2_200_000_000 else m.log_ns


def _bunched(m):     # everything of 1.0-2.5 s logged at 2.5 s: one tie of 1.5 s around the switch
    return 2_500_000_000 if S <= m.log_ns <= 2_500_000_000 else m.log_ns


def _very_late(m):   # the target poses from 2.15 s on logged 3 s late (across the switches at 2.2 and 3.0 s)
    return m.log_ns + 3 * S if m.topic == "/target/pose" and m.log_ns >= 2_150_000_000 else m.log_ns


@pytest.mark.parametrize("how, window, refused", [("late", None, False), ("bunched", None, False),
                                                  ("very_late", None, False), ("very_late", S, True),
                                                  ("late", 1, False)])
def test_estimate_streamed_writes_the_outputs_of_the_whole_order(clean, paper_tables, tmp_path, how, window, refused):
    """``switchobs_bag estimate`` streamed (the default window, or a short one that the recording
    exceeds: then it starts again with the whole order) writes the bag (message for message,
    ``metadata.yaml`` byte for byte) and the CSV (byte for byte) of the run ordered whole, with the
    same counts of unordered parts."""
    bag = _rewrite(clean / "clean", tmp_path / how, {"late": _late, "bunched": _bunched, "very_late": _very_late}[how])
    p = estimator_params(overrides={"gain_table": paper_tables["periodic"], "e0": 5.0})
    kw = {} if window is None else {"window_ns": window}
    a = estimate(bag, p, out=tmp_path / "s" / "o", csv=tmp_path / "s.csv", keep=False, **kw)
    b = estimate(bag, p, out=tmp_path / "w" / "o", csv=tmp_path / "w.csv", keep=False, window_ns=None)
    assert bool(a.whole_order) == refused and not b.whole_order
    assert a.count == b.count > 300 and a.unordered == b.unordered and a.unproven_ties == b.unproven_ties
    assert a.messages_in == b.messages_in and a.rejected == b.rejected
    assert (tmp_path / "s.csv").read_bytes() == (tmp_path / "w.csv").read_bytes()
    # the same name (the file's metadata record holds it); messages deserialised: the CDR padding bytes of
    # rclpy's serialiser are not deterministic, not even between two runs of one order
    meta = [(tmp_path / d / "o" / "metadata.yaml").read_bytes() for d in ("s", "w")]
    assert meta[0] == meta[1]
    assert _messages(tmp_path / "s" / "o") == _messages(tmp_path / "w" / "o")
    if how != "bunched":
        assert a.unordered > 0


@pytest.mark.parametrize("storage", ["mcap", "sqlite3"])
def test_a_bag_that_fails_while_read_leaves_no_output(clean, paper_tables, tmp_path, storage):
    """A data file cut in half fails while the bag is read as it goes (after the output bag is
    opened): one BagError naming the bag, and neither the output bag nor the CSV is left behind."""
    bag = _rewrite(clean / "clean", tmp_path / "cut", lambda m: m.log_ns, storage=storage)
    f = next(p for p in bag.iterdir() if p.suffix in (".mcap", ".db3"))
    f.write_bytes(f.read_bytes()[: f.stat().st_size // 2])
    p = estimator_params(overrides={"gain_table": paper_tables["periodic"], "e0": 5.0})
    with pytest.raises(BagError, match=f"bag {bag}: .*truncated"):
        estimate(bag, p, out=tmp_path / "o", csv=tmp_path / "o.csv", keep=False)
    assert not (tmp_path / "o").exists() and not (tmp_path / "o.csv").exists()
