"""camera_sim's order within a tick: a stamped channel message before the poses on a switching
tick and after them on every other tick, so that the estimator with the default ``switch_horizon``
answers every target pose as its tick's messages arrive, never one tick later; a ``std_msgs/UInt8``
channel in the same places (without a switching instant, a switching tick's poses wait one tick).
The node's callback is run with recording publishers, its messages fed to the
pipeline in the order sent, no DDS."""

from __future__ import annotations

import pytest

import msg_bridge as mb
from switchobs_ros.estimator import PARAMS
from switchobs_ros.pipeline import EstimatorPipeline

S = 1_000_000_000
MS = 1_000_000
EPOCH_NS = 100_000 * S
CHANNEL, CAMERA, TARGET = "camera/active_channel", "camera/pose", "target/pose"


class _Recorder:
    """A publisher that appends ``(topic, message)`` to the tick's list."""

    def __init__(self, topic: str, sent: list) -> None:
        self.topic, self.sent = topic, sent

    def publish(self, msg) -> None:
        self.sent.append((self.topic, msg))


def _ticks(n: int, skip: tuple[int, ...] = (), **params) -> list[list[tuple[str, object]]]:
    """The messages of camera_sim's first ``n`` ticks at 50 Hz (the paper's periodic (2 s, 0.6)
    schedule), per tick in the order published (``skip``: ticks its timer skipped, no messages);
    the truth message left out."""
    from rclpy.parameter import Parameter

    from switchobs_ros.camera_sim import CameraSimNode

    node = CameraSimNode(parameter_overrides=[Parameter("rate", value=50.0),
                                              *(Parameter(k, value=v) for k, v in params.items())])
    try:
        node.timer.cancel()
        node.epoch_ns, sent, ticks = EPOCH_NS, [], []
        node.pubs = {topic: _Recorder(topic, sent) for topic in node.pubs}
        node.pub_truth = _Recorder("sim/truth", [])
        for k in range(n):
            if k not in skip:
                node.publish_tick(k)
            ticks.append(list(sent))
            sent.clear()
        return ticks
    finally:
        node.destroy_node()


def _switching_ticks(ticks) -> set[int]:
    """The ticks whose channel differs from the tick published before's (tick 0 included)."""
    out, last = set(), None
    for k, msgs in enumerate(ticks):
        if not msgs:
            continue
        ch = next(mb.read_channel(m, 2)[0] for t, m in msgs if t == CHANNEL)
        if ch != last:
            out.add(k)
        last = ch
    return out


@pytest.mark.parametrize(("skip", "params", "first"), [
    ((), {}, {0, 60, 100}),                   # channel 1 for 1.2 s, channel 2 for 0.8 s, channel 1 again
    ((), {"stamp_offset_ms": 2.0}, {0, 60, 100}),      # the switching instants shifted, not the ticks
    ((60, 61), {}, {0, 62, 100}),             # the timer skipped the switching tick: the next one switches
])
def test_a_stamped_channel_comes_first_only_on_a_switching_tick(ros_node, skip, params, first):
    ticks = _ticks(150, skip, **params)
    assert _switching_ticks(ticks) == first
    for k, msgs in enumerate(ticks):
        topics = [t for t, _ in msgs]
        if k in skip:
            assert topics == []
            continue
        assert set(topics) == {CHANNEL, CAMERA, TARGET}
        assert topics.index(CHANNEL) == (0 if k in first else 2), (k, topics)


def test_an_unstamped_channel_has_the_same_order_and_channel_last_comes_last(ros_node):
    ticks = _ticks(110, channel_type="std_msgs/msg/UInt8")
    for k, msgs in enumerate(ticks):
        assert [t for t, _ in msgs].index(CHANNEL) == (0 if k in (0, 60, 100) else 2)
    for msgs in _ticks(70, channel_last=True):
        assert [t for t, _ in msgs].index(CHANNEL) == 2


def _answered_by_tick(ticks, paper_tables, reorder=None) -> dict[int, int]:
    """Feed the ticks to the estimator's pipeline (default parameters: ``switch_horizon`` 0.9, exact
    stamps) in their order, one source timestamp per message from one clock; ``reorder`` rearranges
    each tick's messages first. Returns, per answered tick, the tick whose messages answered it."""
    c = {p.name: p.default for p in PARAMS}
    c.update(gain_table=paper_tables["periodic"], e0=20.0)
    pl = EstimatorPipeline.from_params(c)
    stamps = {EPOCH_NS + k * 20 * MS: k for k in range(len(ticks))}
    src, answered = 10 * S, {}
    for k, msgs in enumerate(ticks):
        now_ns, now_mono = EPOCH_NS + k * 20 * MS + 2 * MS, k * 0.02
        for topic, msg in (reorder(msgs) if reorder else msgs):
            src += 50_000
            if topic == CHANNEL:
                out = pl.on_channel(msg, src_ns=src, now_mono=now_mono, seq=k)
            else:
                out = pl.on_pose("camera" if topic == CAMERA else "target", msg, now_ns, now_mono, src)
            answered.update({stamps[e.stamp_ns]: k for e in out})
    return answered


def test_an_unstamped_channel_answers_all_but_the_switching_ticks_by_their_own_messages(ros_node, paper_tables):
    """``std_msgs/UInt8`` has no switching instant, hence no horizon: a switching tick's poses (the
    channel message before them) wait for the next tick's message; every other tick is answered by its
    own, the repetition after its poses."""
    answered = _answered_by_tick(_ticks(110, channel_type="std_msgs/msg/UInt8"), paper_tables)
    assert sorted(answered) == list(range(110))
    assert {k for k, by in answered.items() if by != k} == {0, 60, 100}
    assert all(answered[k] == k + 1 for k in (0, 60, 100))


def test_every_sample_is_answered_by_its_own_ticks_messages(ros_node, paper_tables):
    """Through two switches (the last tenth of each residence, ticks 54-59 and 96-99, beyond the
    horizon): every tick answered by its own messages. The same messages with the channel first
    on every tick leave the last tenth waiting one tick for the next heartbeat."""
    ticks = _ticks(110)
    answered = _answered_by_tick(ticks, paper_tables)
    assert answered == {k: k for k in range(110)}
    channel_first = _answered_by_tick(ticks, paper_tables,
                                      reorder=lambda msgs: sorted(msgs, key=lambda tm: tm[0] != CHANNEL))
    late = sorted(k for k, by in channel_first.items() if by != k)
    # beyond 0.9 of the residences (1.08 s of channel 1's 1.2 s, 0.72 s of channel 2's 0.8 s)
    assert late == [*range(54, 60), *range(96, 100)]
    assert all(channel_first[k] == k + 1 for k in late)


def test_a_generated_bag_holds_camera_sims_order(ros_node):
    """``switchobs_bag generate`` writes each tick's messages in the order camera_sim publishes them
    (one owner: ``SensorOutputs.messages``), so a replay answers as the live node does."""
    from switchobs_ros.bag.generate import GenerateConfig, scenario_ticks

    for kind in ("switchobs_msgs/msg/ActiveChannel", "std_msgs/msg/UInt8"):
        live = [[t for t, _ in msgs] for msgs in _ticks(110, channel_type=kind)]
        bag = [[t.lstrip("/") for t, _ in msgs if t not in ("/clock", "/sim/truth")]
               for _, msgs in scenario_ticks(GenerateConfig(rate=50.0, duration=2.18, channel_type=kind))]
        assert len(bag) == 110 and bag == live
