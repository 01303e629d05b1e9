"""``switchobs_bag record``: subscribe to topics and write a rosbag2 bag.

Each message is written as the received CDR bytes (raw subscriptions) with its receive time on
the node clock as log time: the simulated time from ``/clock`` with ``use_sim_time`` (messages
received before the first ``/clock`` are dropped and counted), the system time otherwise.

Topics and types: the node contract's types for its topics (the estimator's inputs and outputs,
``/sim/truth``, ``/diagnostics``, ``/clock``); any other topic's type is taken from the ROS graph
(waiting up to ``discover_timeout`` for a publisher). QoS: reliable if every publisher seen at
start offers reliable (else best effort), transient local if every one offers it, keep last
1000, as rosbag2 adapts to its publishers; with no publisher yet, the contract's QoS for that
topic (poses best effort, others reliable).

Stops after ``duration`` seconds (wall), after ``count`` messages, or on SIGINT/SIGTERM; the bag
is closed properly in every case (metadata.yaml written).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

from switchobs_core.ranges import check_seconds

from .io import CHANNEL_TYPES, CONTRACT_TYPES, BagError, BagOut, msg_class, qos_kind

__all__ = ["RecordConfig", "default_topics", "record"]


def default_topics(estimator_ns: str = "/estimator",
                   bodies: tuple = ("camera", "agent1", "agent2")) -> dict[str, str]:
    """The estimator's inputs and outputs, ``/sim/truth`` and ``/diagnostics`` with their types."""
    ns = "/" + estimator_ns.strip("/")
    out = {t: CONTRACT_TYPES[t] for t in ("/camera/active_channel", "/camera/pose", "/target/pose", "/sim/truth",
                                          "/diagnostics")}
    out[f"{ns}/state"] = "std_msgs/msg/Float64MultiArray"
    out[f"{ns}/envelope"] = "std_msgs/msg/Float64MultiArray"
    for b in bodies:
        out[f"{ns}/{b}/odom"] = "nav_msgs/msg/Odometry"
    return out


@dataclass
class RecordConfig:
    topics: tuple = ()                # absolute names; empty: default_topics()
    storage: str = "mcap"
    duration: float = 0.0             # wall seconds; 0 = until stopped
    count: int = 0                    # messages; 0 = no limit
    discover_timeout: float = 5.0
    wait_publishers: tuple | None = None   # wait for a publisher on these topics (() = all) before "recording"
    wait_timeout: float = 30.0
    depth: int = 1000


def _subscription_qos(node, topic: str, depth: int):
    from rclpy.qos import QoSDurabilityPolicy, QoSHistoryPolicy, QoSProfile, QoSReliabilityPolicy

    infos = node.get_publishers_info_by_topic(topic)
    if infos:
        reliable = all(i.qos_profile.reliability == QoSReliabilityPolicy.RELIABLE for i in infos)
        transient = all(i.qos_profile.durability == QoSDurabilityPolicy.TRANSIENT_LOCAL for i in infos)
    else:
        reliable = qos_kind(topic) not in ("sensor", "clock")
        transient = False
    return QoSProfile(history=QoSHistoryPolicy.KEEP_LAST, depth=depth,
                      reliability=QoSReliabilityPolicy.RELIABLE if reliable else QoSReliabilityPolicy.BEST_EFFORT,
                      durability=QoSDurabilityPolicy.TRANSIENT_LOCAL if transient else QoSDurabilityPolicy.VOLATILE)


def record(out_path, cfg: RecordConfig, *, node, log=print, should_stop=lambda: False) -> dict:
    """Record on ``node`` (an rclpy node; its clock gives the log times) into a new bag."""
    import rclpy

    for name in ("duration", "wait_timeout", "discover_timeout"):
        check_seconds(getattr(cfg, name), "--" + name.replace("_", "-"), exc=BagError)
    if cfg.count < 0:
        raise BagError(f"--count must be >= 0 (0: no limit); got {cfg.count}")
    wanted = default_topics() if not cfg.topics else {t: None for t in cfg.topics}
    known = default_topics()
    known.update(CONTRACT_TYPES)
    types: dict[str, str] = {}
    deadline = time.monotonic() + cfg.discover_timeout
    offered = dict(node.get_topic_names_and_types())
    for t in wanted:
        if t in known:      # the contract's type, or the other channel type its publisher offers
            types[t] = next((ty for ty in CHANNEL_TYPES if ty in offered.get(t, ())), known[t]) \
                if known[t] in CHANNEL_TYPES else known[t]
            continue
        while True:
            graph = dict(node.get_topic_names_and_types())
            if t in graph:
                types[t] = graph[t][0]
                break
            if time.monotonic() > deadline or should_stop():
                raise BagError(f"topic {t}: type unknown (no publisher within {cfg.discover_timeout:g} s); "
                               "start its publisher first or record the contract's topics")
            rclpy.spin_once(node, timeout_sec=0.05)
    if cfg.wait_publishers is not None:
        waited = list(cfg.wait_publishers) or list(types)
        deadline = time.monotonic() + cfg.wait_timeout
        while any(node.count_publishers(t) == 0 for t in waited):
            if time.monotonic() > deadline:
                missing = [t for t in waited if node.count_publishers(t) == 0]
                raise TimeoutError(f"no publisher on {', '.join(missing)} within {cfg.wait_timeout:g} s")
            if should_stop():
                break
            rclpy.spin_once(node, timeout_sec=0.05)
    counts = dict.fromkeys(types, 0)
    state = {"n": 0, "dropped": 0, "first": None, "last": None}
    bag = BagOut(out_path, cfg.storage)
    clock = node.get_clock()
    sim = node.get_parameter("use_sim_time").value

    def callback_for(topic):
        def cb(data: bytes) -> None:
            now = clock.now().nanoseconds
            if sim and now == 0:
                state["dropped"] += 1
                return
            bag.write(topic, now, data)
            counts[topic] += 1
            state["n"] += 1
            state["first"] = now if state["first"] is None else state["first"]
            state["last"] = now
        return cb

    subs = []
    try:
        for t, ty in types.items():
            bag.add(t, ty)
            subs.append(node.create_subscription(msg_class(ty), t, callback_for(t),
                                                 _subscription_qos(node, t, cfg.depth), raw=True))
        log(f"recording {len(types)} topics to {out_path} ({cfg.storage}"
            f"{', sim time' if sim else ''}): {', '.join(types)}")
        t_end = time.monotonic() + cfg.duration if cfg.duration > 0 else None
        while not should_stop():
            if t_end is not None and time.monotonic() >= t_end:
                break
            if cfg.count and state["n"] >= cfg.count:
                break
            rclpy.spin_once(node, timeout_sec=0.05)
    finally:
        for s in subs:
            node.destroy_subscription(s)
        bag.close()
    return {"path": str(out_path), "messages": state["n"], "per_topic": counts,
            "dropped_before_clock": state["dropped"], "first_ns": state["first"], "last_ns": state["last"]}
