"""Outputs on demand (switchobs_ros.demand): the estimator builds and publishes an optional output
only while a subscription is matched to it, and forms the covariance only while an output that
carries it is listened to, and only for the estimates such an output takes at its decimation;
~/state is always published."""

from __future__ import annotations

import time

import numpy as np
from geometry_msgs.msg import PoseStamped
from nav_msgs.msg import Odometry
from rclpy.parameter import Parameter
from ros_harness import EstimatorIO, spin_until
from std_msgs.msg import Float64MultiArray, UInt8

import msg_bridge as mb
from switchobs_ros import qos
from switchobs_ros.demand import LISTEN_PERIOD, LISTEN_PERIOD_NO, Demand, listened
from switchobs_ros.estimator import EstimatorNode


class _Pub:
    def __init__(self, n: int = 0):
        self.n = n
        self.asked = 0

    def get_subscription_count(self) -> int:
        self.asked += 1
        return self.n


def test_demand_keeps_a_yes_and_a_no_for_their_periods():
    now = [0.0]
    pubs = [_Pub(), _Pub()]
    d = Demand(lambda: list(zip(("odometry", "covariance"), pubs)), period=0.1, period_no=0.02, clock=lambda: now[0])
    assert not d.covariance_wanted() and not d.covariance_wanted() and d.kinds == set()
    assert [p.asked for p in pubs] == [1, 1]              # a no is kept for period_no
    pubs[1].n = 1
    now[0] = 0.01
    assert not d.covariance_wanted()
    now[0] = 0.02
    assert d.covariance_wanted() and [p.asked for p in pubs] == [2, 2] and d.kinds == {"covariance"}
    pubs[1].n = 0
    now[0] = 0.07
    assert d.covariance_wanted()                          # a yes kept for the period
    now[0] = 0.13
    assert not d.covariance_wanted()                      # then asked again
    pubs[0].n = 1
    d.expire()
    assert d.covariance_wanted() and d.kinds == {"odometry"}


def test_listened_keeps_each_publishers_answer_for_its_period():
    now = [10.0]
    clock = lambda: now[0]
    a, b = _Pub(0), _Pub(1)
    assert not listened(a, clock) and listened(b, clock) and not listened(None, clock)
    a.n, b.n = 1, 0
    now[0] += LISTEN_PERIOD_NO * 0.99
    assert not listened(a, clock) and listened(b, clock) and (a.asked, b.asked) == (1, 1)   # kept
    now[0] += LISTEN_PERIOD_NO * 0.02
    assert listened(a, clock) and a.asked == 2           # a new subscriber: seen after at most period_no
    now[0] = 10.0 + LISTEN_PERIOD * 0.99
    assert listened(b, clock) and b.asked == 1           # a yes kept for the period
    now[0] = 10.0 + LISTEN_PERIOD * 1.01
    assert not listened(b, clock) and b.asked == 2       # then asked again


def test_demands_refresh_answers_listened_for_the_carriers():
    pubs = [_Pub(1), _Pub(0)]
    d = Demand(lambda: list(zip(("odometry", "covariance"), pubs)))
    assert d.covariance_wanted() and [p.asked for p in pubs] == [1, 1]
    pubs[0].n = 0
    assert listened(pubs[0]) and pubs[0].asked == 1      # the refresh's yes, kept LISTEN_PERIOD (0.5 s)


def test_demands_refresh_asks_a_kinds_publishers_up_to_the_first_listened():
    odom = [_Pub(0), _Pub(1), _Pub(1)]
    cov = _Pub(0)
    d = Demand(lambda: [("odometry", p) for p in odom] + [("covariance", cov)])
    assert d.covariance_wanted() and d.kinds == {"odometry"}
    assert [p.asked for p in odom] == [1, 1, 0] and cov.asked == 1
    odom[1].n = 0
    d.expire()
    assert d.covariance_wanted() and d.kinds == {"odometry"} and [p.asked for p in odom] == [2, 2, 1]
    odom[2].n = 0
    d.expire()
    assert not d.covariance_wanted() and d.kinds == set() and [p.asked for p in odom] == [3, 3, 2]


def _feed(est: EstimatorNode, io: EstimatorIO, k0: int, n: int) -> None:
    base = time.time_ns()
    for k in range(k0, k0 + n):
        s = base + k * 10_000_000
        io.pub_camera.publish(mb.xy_to_pose((0.1, 0.2), s, "map"))
        io.pub_target.publish(mb.xy_to_pose((3.0, 1.0), s, "map"))
    end = time.monotonic() + 10
    while est.pipeline.updates < k0 - 1 + n and time.monotonic() < end:
        est._drain_inputs()
        time.sleep(0.01)


def _inputs(ros_node):
    """The test's publishers of the estimator's inputs (channel, camera and target poses)."""
    io = EstimatorIO.__new__(EstimatorIO)
    io.node = ros_node
    io.pub_channel = ros_node.create_publisher(UInt8, "camera/active_channel", qos.CHANNEL_PUB)
    io.pub_camera = ros_node.create_publisher(PoseStamped, "camera/pose", qos.SENSOR)
    io.pub_target = ros_node.create_publisher(PoseStamped, "target/pose", qos.SENSOR)
    return io


def test_node_publishes_optional_outputs_only_to_subscribers(paper_tables, ros_node):
    est = EstimatorNode(parameter_overrides=[Parameter("gain_table", value=paper_tables["periodic"]),
                                             Parameter("reorder_window_ms", value=0.0),
                                             Parameter("noise.measurement_std", value=0.01)])
    try:
        # the test's inputs, and of the outputs only ~/state and agent1's odometry
        io = _inputs(ros_node)
        got = {"state": [], "odom": []}
        ros_node.create_subscription(Float64MultiArray, "/estimator/state", got["state"].append, qos.TRUTH)
        odom = ros_node.create_subscription(Odometry, "/estimator/agent1/odom", got["odom"].append, qos.TRUTH)
        assert spin_until(ros_node, lambda: all(p.get_subscription_count() > 0 for p in
                                                (io.pub_channel, io.pub_camera, io.pub_target))
                          and est.pub_odom[1].get_subscription_count() > 0, 20.0)
        pl = est.pipeline
        io.pub_channel.publish(UInt8(data=1))
        end = time.monotonic() + 10
        while pl.channel != 1 and time.monotonic() < end:
            est._drain_inputs()
            time.sleep(0.01)
        _feed(est, io, 1, 20)
        n = est.published
        assert pl.updates == 20 and n["state"] == 20
        assert n["odometry"] == 20                   # one body of three is listened to
        assert n["envelope"] == n["covariance"] == n["typed"] == n["markers"] == 0
        assert est._covariance_due(0)                # the odometry carries P: formed for the next estimate
        assert spin_until(ros_node, lambda: len(got["odom"]) >= 20 and len(got["state"]) >= 20, 10.0)
        assert all(any(c != 0.0 for c in m.pose.covariance) for m in got["odom"])
        # nobody listens to an output carrying P any more: P is no longer formed, odometry not sent
        ros_node.destroy_subscription(odom)
        assert spin_until(ros_node, lambda: est.pub_odom[1].get_subscription_count() == 0, 20.0)
        time.sleep(0.15)                             # past the period a yes is kept
        seen = []
        publish_all = est._publish_all
        est._publish_all = lambda estimates: (seen.extend(estimates), publish_all(estimates))
        _feed(est, io, 21, 10)
        assert pl.updates == 30 and n["state"] == 30 and n["odometry"] == 20
        assert len(seen) == 10 and all(e.P is None for e in seen)     # P no longer formed
        assert not est._covariance_due(0)
    finally:
        est.destroy_node()


def test_node_forms_P_only_for_the_estimates_its_outputs_take(paper_tables, ros_node):
    """``output.covariance_every: 5`` and ``output.odometry_every: 5``, both listened: ``P`` is formed
    for the 0th, 5th, ... estimate only, and what goes out is that estimate's ``P``."""
    est = EstimatorNode(parameter_overrides=[Parameter("gain_table", value=paper_tables["periodic"]),
                                             Parameter("reorder_window_ms", value=0.0),
                                             Parameter("noise.measurement_std", value=0.01),
                                             Parameter("output.covariance_every", value=5),
                                             Parameter("output.odometry_every", value=5)])
    try:
        io = _inputs(ros_node)
        got = {"cov": [], "odom": []}
        ros_node.create_subscription(Float64MultiArray, "/estimator/covariance", got["cov"].append, qos.TRUTH)
        ros_node.create_subscription(Odometry, "/estimator/agent1/odom", got["odom"].append, qos.TRUTH)
        assert spin_until(ros_node, lambda: all(p.get_subscription_count() > 0 for p in
                                                (io.pub_channel, io.pub_camera, io.pub_target, est.pub_cov))
                          and est.pub_odom[1].get_subscription_count() > 0, 20.0)
        seen = []
        publish_all = est._publish_all
        est._publish_all = lambda estimates: (seen.extend(estimates), publish_all(estimates))
        io.pub_channel.publish(UInt8(data=1))
        end = time.monotonic() + 10
        while est.pipeline.channel != 1 and time.monotonic() < end:
            est._drain_inputs()
            time.sleep(0.01)
        _feed(est, io, 1, 20)
        assert len(seen) == 20
        assert [e.P is not None for e in seen] == [k % 5 == 0 for k in range(20)]
        assert est.published["covariance"] == 4 and est.published["odometry"] == 4
        assert spin_until(ros_node, lambda: len(got["cov"]) >= 4 and len(got["odom"]) >= 4, 10.0)
        taken = [e for e in seen if e.P is not None]
        agent1 = next(b for b in est.bodies if b.name == "agent1")
        for e, cov, odom in zip(taken, got["cov"], got["odom"]):
            c = mb.unpack_labelled(cov)
            assert c.stamp_ns == e.stamp_ns
            np.testing.assert_array_equal(c.values, e.P.ravel())                    # the estimate's P, exactly
            assert odom.pose.pose.position.x == e.x_hat[agent1.p_x]
            assert odom.pose.covariance[0] == e.P[agent1.p_x, agent1.p_x]
            assert odom.twist.covariance[7] == e.P[agent1.v_y, agent1.v_y]
    finally:
        est.destroy_node()
