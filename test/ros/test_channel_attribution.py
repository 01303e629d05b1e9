"""switchobs_ros.attribution.ChannelAttribution on its own: the verdicts it gives a pending sample
(switchobs_ros.pairing) from the channel history, sequence gaps, late messages and the reorder
window; and the pairing of parts by stamp. The behaviour through the pipeline is in
test_attribution.py."""

from __future__ import annotations

import numpy as np
import pytest

from msg_bridge import Reason
from switchobs_ros.attribution import (
    CHANNEL_HISTORY,
    ChannelAttribution,
    Resolution,
    Verdict,
    lost_between,
    sequence,
)
from switchobs_ros.pairing import DeadTime, Pairing, Pending
from switchobs_ros.sources import Source

MS = 1_000_000
WINDOW = 50 * MS
#: The paper interface: the camera pose (shared rows 0, 1 of both channels), the target pose
#: (rows 2, 3 of the channel the channel topic names).
CAMERA = Source(0, "camera/pose", "geometry_msgs/msg/PoseStamped", ("x", "y"), None, ((0, 1), (0, 1)), True,
                None, True)
TARGET = Source(1, "target/pose", "geometry_msgs/msg/PoseStamped", ("x", "y"), None, ((2, 3), (2, 3)), False,
                None, True)
#: One topic per channel (config/cart_pair.yaml): no channel topic.
LEFT = Source(0, "left/point", "geometry_msgs/msg/PointStamped", ("point.x",), 1, ((0,), ()), False, None, False)
RIGHT = Source(1, "right/point", "geometry_msgs/msg/PointStamped", ("point.x",), 2, ((), (0,)), False, None, False)


def _sample(stamp_ns: int, parts: dict[int, int | None], since: float = 0.0, arrival: int = 0) -> Pending:
    """A pending sample with parts ``{source index: source timestamp}``."""
    pairing = Pairing((CAMERA, TARGET), (4, 4))
    pend = None
    for i, src in parts.items():
        pend = pairing.add(i, stamp_ns, np.zeros(2), src, arrival, since)
    return pend


def _att(window: int = WINDOW) -> ChannelAttribution:
    return ChannelAttribution((CAMERA, TARGET), "camera/active_channel", window)


def test_the_latest_channel_sent_before_the_sample_once_a_later_one_arrived():
    att = _att()
    assert att.remember(1000, 1, seq=1) == []
    pend = _sample(5, {0: 1010, 1: 1020})
    assert att.resolve(pend, 0.0) == Resolution(Verdict.CHANNEL, 1, certain=False)    # may still change
    assert att.remember(1030, 2, seq=2) == []
    assert att.resolve(pend, 0.0) == Resolution(Verdict.CHANNEL, 1, certain=True)
    # a sample sent after the switch message takes channel 2 (not arrival order)
    assert att.resolve(_sample(6, {1: 1040}), 0.0).channel == 2


def test_the_window_makes_the_channel_certain():
    att = _att()
    att.remember(1000, 2, seq=7)
    pend = _sample(5, {1: 1010}, since=10.0)
    assert not att.resolve(pend, 10.0 + 0.049).certain
    assert att.resolve(pend, 10.0 + 0.050) == Resolution(Verdict.CHANNEL, 2, certain=True)
    assert att.resolve(pend, 10.0, force=True).certain
    assert att.guessed(pend)                                     # answered on the window's expiry


def test_sent_before_any_channel_is_no_channel():
    att = _att()
    pend = _sample(5, {1: 900}, since=0.0)
    assert att.resolve(pend, 0.0) == Resolution(Verdict.NO_CHANNEL, certain=False)      # waits for one
    assert att.resolve(pend, 1.0) == Resolution(Verdict.NO_CHANNEL, certain=True)
    att.remember(1000, 1, seq=1)
    assert att.resolve(pend, 0.0) == Resolution(Verdict.NO_CHANNEL, certain=True)
    assert Verdict.NO_CHANNEL.rejection == (Reason.NO_CHANNEL, "no active channel when it was sent")


def test_older_than_the_history_kept_is_uncertain():
    att = _att()
    for k in range(CHANNEL_HISTORY + 1):
        att.remember(1000 + 10 * k, 1 + k % 2, seq=k + 1)
    assert len(att.sequence_numbers) == CHANNEL_HISTORY
    assert att.resolve(_sample(5, {1: 1005}), 0.0) == Resolution(Verdict.UNCERTAIN)
    assert Verdict.UNCERTAIN.rejection[0] is Reason.AMBIGUOUS_CHANNEL


def test_a_gap_in_the_sequence_numbers_is_lost():
    att = _att()
    att.remember(1000, 1, seq=4)
    att.remember(1100, 1, seq=7)                 # 5 and 6 lost
    assert att.lost == 2
    assert att.resolve(_sample(5, {1: 1050}), 0.0) == Resolution(Verdict.LOST)
    assert att.resolve(_sample(6, {1: 1150}), 0.0).verdict is Verdict.CHANNEL
    assert "channel messages were lost" in Verdict.LOST.rejection[1]
    # a restarted publisher numbers from 1 again: not a gap
    att.remember(1200, 2, seq=1)
    assert att.lost == 2 and att.resolve(_sample(7, {1: 1150}), 0.0).verdict is Verdict.CHANNEL


def test_sequence_numbers_and_losses():
    assert (lost_between(61, 1), lost_between(61, 3), lost_between(4, 5), lost_between(4, 7),
            lost_between(None, 9), lost_between(9, None)) == (0, 2, 0, 2, 0, 0)
    assert (sequence(None), sequence(0), sequence(2**64 - 1), sequence(5)) == (None, None, None, 5)


def test_a_gap_around_an_answer_on_expiry_withdraws_and_a_late_message_too():
    att = _att()
    att.remember(1000, 1, seq=1)
    pend = _sample(5, {0: 1010, 1: 1020})
    assert att.guessed(pend)
    att.answered(pend, guessed=True)
    why = att.remember(1100, 1, seq=4)
    assert att.lost == 2 and len(why) == 1 and "lost (publication sequence 1 then 4)" in why[0]
    # a channel message sent before an answered sample, naming another channel: late
    why = att.remember(1015, 2, seq=None)
    assert att.late == 1 and "raise reorder_window_ms" in why[0]
    # the same channel as the history says: nothing changes for the answered samples
    assert att.remember(1016, 2, seq=None) == [] and att.late == 1


def test_an_invalid_channel_message_keeps_the_channel_and_closes_the_gap():
    att = _att()
    att.remember(1000, 2, seq=1)
    assert att.remember_invalid(1050, 2) == []              # seq 2 received (its value invalid)
    att.remember(1100, 2, seq=3)
    assert att.lost == 0 and att.sequence_numbers == (1, 2, 3)
    assert att.resolve(_sample(5, {1: 1060}), 0.0) == Resolution(Verdict.CHANNEL, 2)
    assert att.remember_invalid(None, 4) == [] and att.remember_invalid(1200, None) == []


def test_one_channel_sources_name_their_channel_and_disagree_as_a_conflict():
    att = ChannelAttribution((LEFT, RIGHT), None, WINDOW)
    pairing = Pairing((LEFT, RIGHT), (1, 1))
    left = pairing.add(0, 5, np.zeros(1), None, 0, 0.0)
    assert att.resolve(left, 0.0) == Resolution(Verdict.CHANNEL, 1)
    both = pairing.add(1, 5, np.zeros(1), None, 0, 0.0)
    assert att.resolve(both, 0.0) == Resolution(Verdict.CONFLICT)
    assert Verdict.CONFLICT.rejection[0] is Reason.AMBIGUOUS_CHANNEL
    assert not att.guessed(both)


def test_without_source_timestamps_the_arrival_channel_decides():
    att = _att()
    att.switch(2, {"camera/pose": 10, "target/pose": 20})
    assert att.channel == 2 and att.switch_ns == 20
    assert att.resolve(_sample(5, {1: None}, arrival=1), 0.0) == Resolution(Verdict.CHANNEL, 1)
    assert att.resolve(_sample(5, {1: None}, arrival=0), 0.0) == Resolution(Verdict.CHANNEL, 2)
    # a target part stamped at or before the switch was taken on the previous channel
    old = att.refuse(TARGET, 20, None, None)
    assert old is not None and old.reason is Reason.STALE_AFTER_SWITCH
    assert att.refuse(TARGET, 21, None, None) is None
    att.reset()
    assert att.switch_ns is None and att.channel == 2


def test_no_channel_yet_is_refused_when_arrival_order_decides():
    att = _att()
    assert att.refuse(TARGET, 5, None, None).reason is Reason.NO_CHANNEL
    assert att.refuse(TARGET, 5, 1000, None) is None                    # it waits in the window
    assert _att(window=0).refuse(TARGET, 5, 1000, None).reason is Reason.NO_CHANNEL
    assert att.refuse(CAMERA, 5, None, None).reason is Reason.NO_CHANNEL   # the camera too (no channel topic part)
    assert ChannelAttribution((LEFT, RIGHT), None, WINDOW).refuse(LEFT, 5, None, None) is None   # names its own


@pytest.mark.parametrize("verdict", [v for v in Verdict if v is not Verdict.CHANNEL])
def test_every_verdict_but_channel_has_a_rejection(verdict):
    reason, detail = verdict.rejection
    assert reason in (Reason.NO_CHANNEL, Reason.AMBIGUOUS_CHANNEL) and detail


# ------------------------------------------------------------------ pairing
def test_pairing_completes_supersedes_and_times_out():
    pairing = Pairing((CAMERA, TARGET), (4, 4))
    cam = pairing.add(0, 100, np.array([1.0, 2.0]), 7, 1, 0.0)
    assert not pairing.complete(cam, 1) and not pairing.due(cam, 1, 0.1, 0.2)
    assert pairing.due(cam, 1, 0.3, 0.2)                     # waited longer than the timeout
    newer = pairing.add(0, 200, np.array([1.0, 2.0]), None, 1, 0.0)
    pairing.add(1, 200, np.array([3.0, 4.0]), None, 1, 0.0)
    assert pairing.complete(newer, 2)
    pairing.settle(200)
    assert pairing.due(cam, 1, 0.0, None)                    # superseded: goes alone
    assert pairing.oldest() is cam and pairing.pop(100) is cam and pairing.oldest() is newer
    m = pairing.measurement(newer, 2)
    assert m.channel == 2 and m.rows is None and m.y.tolist() == [1.0, 2.0, 3.0, 4.0]
    alone = pairing.measurement(cam, 1)
    assert alone.rows == (0, 1) and alone.y.tolist() == [1.0, 2.0]
    assert pairing.topic(newer) == "target/pose" and pairing.topic(cam) == "camera/pose"
    assert pairing.clear() == 2 and pairing.pending == {} and pairing.upto == -1


def test_dead_time_blind_until_a_channel_part():
    dead = DeadTime(300 * MS, shared0=0)
    dead.accepted(CAMERA, 100 * MS, 80 * MS)                 # period 20 ms
    assert dead.period_ns == 20 * MS
    assert dead.certainly_blind(100 * MS)                    # the dead time's first shared sample
    assert dead.certainly_blind(379 * MS) and not dead.certainly_blind(380 * MS)
    dead.accepted(TARGET, 400 * MS, None)
    assert not dead.certainly_blind(120 * MS)                # the new channel's part came
    dead.switched()
    assert dead.certainly_blind(500 * MS)
    assert not DeadTime(0, shared0=0).certainly_blind(0)


def test_a_certain_resolution_by_stamps_is_kept_until_a_switching_message_or_a_part_arrives():
    """By stamps, a certain answer is asked again for the same sample as it is paired, advanced and
    answered, and kept: the same answer (one instance) while nothing changed; a switching message
    that arrives after it (a late one: a switch at or before the sample) or a new part makes it
    resolved afresh."""
    att = _att()
    att.stamped.horizon = {1: 500 * MS, 2: 500 * MS}
    assert att.remember_switch(100 * MS, 1, 100 * MS, seq=1) == []
    pend = _sample(150 * MS, {0: 150 * MS})
    first = att.resolve(pend, 0.0)
    assert first == Resolution(Verdict.CHANNEL, 1, certain=True)       # within the horizon: certain at once
    assert att.resolve(pend, 0.0) is first and att.resolve(pend, 1.0) is first
    pend.parts[1] = _sample(150 * MS, {1: 150 * MS}).parts[1]            # the target's part
    assert att.resolve(pend, 0.0) == first
    assert att.answered(pend, False) is None and att.stamped.answered == 150 * MS
    # a switch to channel 2 at 120 ms arrives after the sample was answered: withdraws, and the
    # same sample now reads as channel 2 (never the kept channel 1)
    assert att.remember_switch(120 * MS, 2, 160 * MS, seq=2)
    assert att.resolve(pend, 0.0) == Resolution(Verdict.CHANNEL, 2, certain=True)
    assert att.resolve(pend, 0.0, force=True) == Resolution(Verdict.CHANNEL, 2, certain=True)


def test_a_kept_resolution_is_resolved_afresh_when_a_part_is_replaced():
    """A sample re-stamped to its target's stamp (tolerance 5 ms) whose camera part is then replaced by the
    camera's next message on that stamp: the same stamp, the same number of parts and the same switching
    messages, but a newer part, so a switching message no longer arrived after every part (a recording
    without source timestamps) and the channel is not certain any more: resolved afresh, as an attribution
    that never kept an answer resolves it."""

    def run(keep: bool) -> Resolution:
        att = ChannelAttribution((CAMERA, TARGET), "camera/active_channel", WINDOW, 5 * MS)
        att.stamped.horizon = {1: 0, 2: 0}
        pairing = Pairing((CAMERA, TARGET), (4, 4), 5 * MS)
        v = np.zeros(2)
        att.remember_switch(100 * MS, 1, None, seq=1)
        a = pairing.add(0, 200 * MS, v, None, 1, 0.0, att.stamped.received)
        assert pairing.add(1, 203 * MS, v, None, 1, 0.0, att.stamped.received) is a and a.stamp_ns == 203 * MS
        att.remember_switch(100 * MS, 1, None, seq=2)       # a repeated switching message, after a's parts
        if keep:
            assert att.resolve(a, 0.0) == Resolution(Verdict.CHANNEL, 1, certain=True)
        old = pairing.add(1, 150 * MS, v, None, 1, 0.0, att.stamped.received)   # a late, older sample
        att.resolve(old, 0.0)
        assert pairing.add(0, 203 * MS, v, None, 1, 0.0, att.stamped.received) is a and len(a.parts) == 2
        return att.resolve(a, 0.0)

    assert run(True) == run(False) == Resolution(Verdict.CHANNEL, 1, certain=False)
