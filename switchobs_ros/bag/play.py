"""``switchobs_bag play``: publish a bag's messages with their recorded timing, and ``/clock``.

The messages go out as the recorded CDR bytes (no deserialisation), in the bag's order
(:meth:`~switchobs_ros.bag.io.BagIn.messages`), message ``m`` at wall time
``start + (m.log_time - first_log_time) / rate``. Before the messages of each new log time the
player publishes ``/clock`` = that log time (unless ``clock=False``; the bag's own ``/clock``
messages are then skipped), so an estimator with ``use_sim_time:=true`` runs on the bag's
timeline. QoS of each topic as the node contract (:func:`~switchobs_ros.bag.io.qos_for`).

Ordering: ``camera/active_channel`` carries no stamp, and the estimator attributes each target
pose to the latest channel it received. After publishing a channel message whose value
differs from the previous one, the player waits ``channel_lead`` seconds (wall, default 5 ms)
before the next message, so the channel is in before the poses of the new channel. It does
not wait otherwise (the channel is in the bag at every tick).

Looping: after the last message the player starts again at the first; ``/clock`` jumps back,
which resets the estimator (see switchobs_ros.estimator). The player waits ``loop_pause``
seconds (wall) before that ``/clock`` (so the last samples of the pass are handled on the old
clock: handled after the jump they would be rejected as future stamps) and again after it (so
the reset is done before the first samples of the new pass arrive).

Start: it waits until node ``wait_node`` (default ``estimator``; "" = any node) subscribes to
each estimator input topic of the bag (and to ``/clock``), then ``settle`` seconds for the
subscriber side of discovery, then starts. Without a subscriber within ``wait_timeout``: an
error naming the topic (exit 3).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import msg_bridge as mb
from switchobs_core.ranges import check_seconds

from .io import TOPIC_RANK, BagError, BagIn, msg_class, qos_for

__all__ = ["PlayConfig", "play"]

ESTIMATOR_INPUTS = ("/camera/pose", "/target/pose", "/camera/active_channel")


@dataclass
class PlayConfig:
    rate: float = 1.0
    loops: int = 1                     # passes over the bag; 0 = until stopped
    clock: bool = True
    topics: tuple = ()                 # empty: every topic except the estimator's outputs and /diagnostics
    all_topics: bool = False
    estimator_ns: str = "/estimator"
    wait: bool = True
    wait_node: str = "estimator"
    wait_timeout: float = 30.0
    settle: float = 0.5
    channel_lead: float = 0.005
    loop_pause: float = 0.2
    start_delay: float = 0.0


class _Stop(Exception):
    pass


def play(bag_path, cfg: PlayConfig, *, node=None, log=print, should_stop=lambda: False) -> dict:
    """Play the bag (see the module docstring). ``node``: an rclpy node to publish from
    (default: a new node ``switchobs_bag_play``; rclpy must be initialised)."""
    import rclpy
    from rosgraph_msgs.msg import Clock

    if not 1e-6 <= cfg.rate <= 1e6:
        raise BagError(f"--rate (a speed factor) must be in [1e-06, 1e+06]; got {cfg.rate}")
    for name in ("wait_timeout", "settle", "channel_lead", "loop_pause"):
        check_seconds(getattr(cfg, name), "--" + name.replace("_", "-"), exc=BagError)
    with BagIn(bag_path) as bag:
        topics = dict(bag.topics)
        if cfg.topics:
            for t in cfg.topics:
                if t not in topics:
                    raise BagError(f"bag {bag.path}: topic {t} is missing (the bag has: {', '.join(sorted(topics))})")
            chosen = set(cfg.topics)
        elif cfg.all_topics:
            chosen = set(topics)
        else:
            ns = "/" + cfg.estimator_ns.strip("/") + "/"
            chosen = {t for t in topics if not t.startswith(ns) and t != "/diagnostics"}
        if cfg.clock:
            chosen.discard("/clock")
        msgs = bag.messages(sorted(chosen))
    if not msgs:
        raise BagError(f"bag {bag_path}: no messages to play on {', '.join(sorted(chosen)) or 'no topics'}")
    own = node is None
    if own:
        node = rclpy.create_node("switchobs_bag_play")
    try:
        pubs = {t: node.create_publisher(msg_class(topics[t]), t, qos_for(t)) for t in sorted(chosen)}
        pub_clock = node.create_publisher(Clock, "/clock", qos_for("/clock")) if cfg.clock else None
        if cfg.wait:
            _wait(node, pubs, pub_clock, cfg, log, should_stop)
        return _run(msgs, pubs, pub_clock, cfg, log, should_stop)
    finally:
        if own:
            node.destroy_node()


def _wait(node, pubs, pub_clock, cfg: PlayConfig, log, should_stop) -> None:
    need = [t for t in ESTIMATOR_INPUTS if t in pubs] or list(pubs)
    if pub_clock is not None:
        need.append("/clock")

    def subscribed(topic):
        infos = node.get_subscriptions_info_by_topic(topic)
        if not cfg.wait_node:
            return len(infos) > 0
        want = cfg.wait_node.strip("/")
        return any(i.node_name == want or f"{i.node_namespace.rstrip('/')}/{i.node_name}".strip("/") == want
                   for i in infos)

    deadline = time.monotonic() + cfg.wait_timeout
    while True:
        missing = [t for t in need if not subscribed(t)]
        if not missing:
            break
        if should_stop():
            raise _Stop
        if time.monotonic() > deadline:
            who = f"node '{cfg.wait_node}'" if cfg.wait_node else "any node"
            hint = (" (run the estimator with use_sim_time:=true, or play with --no-clock)"
                    if missing == ["/clock"] else "")
            raise TimeoutError(f"no subscription by {who} on {', '.join(missing)} within {cfg.wait_timeout:g} s{hint}")
        time.sleep(0.05)
    # the publishers' side of the match too (best-effort poses sent before it are lost)
    while any(p.get_subscription_count() == 0 for t, p in pubs.items() if t in need) and time.monotonic() < deadline:
        time.sleep(0.02)
    log(f"subscribers present on {', '.join(need)}: starting in {cfg.settle:g} s")
    time.sleep(cfg.settle)


def _run(msgs, pubs, pub_clock, cfg: PlayConfig, log, should_stop) -> dict:
    from rosgraph_msgs.msg import Clock

    t0_log = msgs[0].log_ns
    published = 0
    passes = 0
    late_max = 0.0
    clock_msg = Clock()
    if cfg.start_delay > 0:
        time.sleep(cfg.start_delay)
    try:
        while cfg.loops == 0 or passes < cfg.loops:
            if passes > 0 and pub_clock is not None:
                time.sleep(cfg.loop_pause)        # the last pass's messages are in before the clock goes back
                clock_msg.clock = mb.ns_to_stamp(t0_log)
                pub_clock.publish(clock_msg)
                time.sleep(cfg.loop_pause)
            start = time.perf_counter()
            last_clock = None
            last_channel = None
            for m in msgs:
                due = start + (m.log_ns - t0_log) * 1e-9 / cfg.rate
                now = time.perf_counter()
                if due > now:
                    time.sleep(due - now)
                else:
                    late_max = max(late_max, now - due)
                if should_stop():
                    raise _Stop
                if pub_clock is not None and m.log_ns != last_clock:
                    clock_msg.clock = mb.ns_to_stamp(m.log_ns)
                    pub_clock.publish(clock_msg)
                    last_clock = m.log_ns
                pubs[m.topic].publish(m.data)
                published += 1
                if TOPIC_RANK.get(m.topic) == 1 and m.data != last_channel:
                    last_channel = m.data
                    if cfg.channel_lead > 0:
                        time.sleep(cfg.channel_lead)
                        start += cfg.channel_lead     # keep the timeline: the lead is not a delay
            passes += 1
    except _Stop:
        pass
    time.sleep(0.3)   # let reliable messages out before the publishers go
    return {"published": published, "passes": passes, "max_late_s": late_max}
