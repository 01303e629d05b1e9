"""switchobs_ros.drain: a callback takes the inputs waiting and, while a part of the sample is
surely on its way, polls for it a bounded time instead of returning to a wait."""

from __future__ import annotations

from collections import deque
from types import SimpleNamespace

from switchobs_ros import drain


class _Handle:
    """A subscription's handle whose takes come from a script: per take, a message or None."""

    def __init__(self, script):
        self.script = deque(script)
        self.takes = 0

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False

    def take_message(self, msg_type, raw):
        self.takes += 1
        return self.script.popleft() if self.script else None


def _sub(script):
    return SimpleNamespace(handle=_Handle(script), msg_type=None, raw=True)


def _node(hot, pending=(), n_sources=2, linger_s=1.0):
    timer = []
    pl = SimpleNamespace(sources=[None] * n_sources, pairing=SimpleNamespace(pending=dict(enumerate(pending))),
                         internal_error=lambda where, err: (_ for _ in ()).throw(err))
    return SimpleNamespace(_hot_inputs=hot, LINGER_S=linger_s, DRAIN_MAX=32, pipeline=pl,
                           _arm_pairing_timer=lambda: timer.append(1)), timer


def _handler(name, seen, channel=False):
    def handle(msg, info):
        seen.append((name, msg))
    handle.is_channel = channel
    return handle


def test_linger_returns_the_first_message_in_order_or_none_after_its_budget():
    a, b = _sub([None, None, ("b1", {})]), _sub([None, ("c1", {}), None])
    ha, hb = object(), object()
    got = drain.linger([(a, ha), (b, hb)], budget_s=10.0)
    assert got == (hb, ("c1", {}))                  # the second poll of b, before a's third
    assert (a.handle.takes, b.handle.takes) == (2, 2)
    ticks = iter(range(100))                        # a clock that advances 1 per reading
    empty = _sub([])
    assert drain.linger([(empty, ha)], budget_s=3.0, clock=lambda: next(ticks)) is None
    assert empty.handle.takes == 3                  # polled with the clock at 0, 1 and 2; at 3 (= 0 + 3) it gives up


def test_after_the_channel_the_drain_waits_for_the_poses_on_their_way():
    seen = []
    ch, cam, tgt = _sub([]), _sub([None, None, ("pose_c", {})]), _sub([None, None, None, ("pose_t", {})])
    h_ch, h_cam, h_tgt = _handler("channel", seen, channel=True), _handler("camera", seen), _handler("target", seen)
    node, timer = _node([(ch, h_ch), (cam, h_cam), (tgt, h_tgt)])
    # the camera pose leaves a pending sample without its target part: a second linger catches it
    node.pipeline.pairing.pending = {}
    original = h_cam

    def camera_then_pending(msg, info):
        original(msg, info)
        node.pipeline.pairing.pending = {1: SimpleNamespace(parts={0: None})}
    node._hot_inputs = [(ch, h_ch), (cam, camera_then_pending), (tgt, h_tgt)]
    drain.drain_inputs(node, last=h_ch)
    assert seen == [("camera", "pose_c"), ("target", "pose_t")]
    assert timer == [1]


def test_no_linger_when_nothing_is_on_its_way_or_with_no_budget():
    seen = []
    h = _handler("pose", seen)
    channel = _handler("channel", [], channel=True)
    late = _sub([None, ("late", {})])
    node, _ = _node([(late, h)], pending=[SimpleNamespace(parts={0: None, 1: None})])   # complete
    drain.drain_inputs(node, last=h)
    assert seen == [] and late.handle.takes == 1        # one round, no poll
    late = _sub([None, ("late", {})])
    node, _ = _node([(late, h)], linger_s=0.0)
    drain.drain_inputs(node, last=channel)
    assert seen == [] and late.handle.takes == 1        # budget 0: never lingers
    late = _sub([None, ("late", {})])
    node, _ = _node([(late, h)])
    drain.drain_inputs(node, last=channel)
    assert seen == [("pose", "late")]                   # after the channel: caught by the linger
