"""A driven system over DDS: the cart_pair system (``B u``: a force on cart 1) with its commands on
``~/control`` (a labelled Float64MultiArray ``u_1``) at stamps between the samples. The estimator
holds each command from its stamp on (exact zero-order hold), matches the offline
``SwitchedObserver`` (``update(..., u=...)`` and ``hold_input``) to 1e-9, and no sample's error
exceeds the published exact bound; a command for a time already estimated is rejected and counted;
the bag tools read the same commands."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pytest

import msg_bridge as mb
from switchobs_core.design.kalman import design_kalman
from switchobs_core.model.scenarios import load_system
from switchobs_core.model.schedule import Cycle, PeriodicSchedule
from switchobs_core.runtime.observer import SwitchedObserver
from switchobs_core.sim.plant import Plant
from switchobs_core.table.gains import kalman_table

REPO = Path(__file__).resolve().parents[2]
SYSTEM = str(REPO / "config" / "cart_pair.yaml")
CYC = Cycle.from_ts(2.0, 0.6)
RATE = 50.0
X0 = np.array([1.0, 0.2, -0.5, 0.1])
K = 301                      # samples: 6 s, three cycles
PARAMS = {"system": SYSTEM, "schedule.mode": "periodic", "schedule.tau": [2.0], "schedule.s": [0.6],
          "e0": float(np.linalg.norm(X0)) * 1.01, "publish_covariance": False, "output.markers_every": 10}


@pytest.fixture(scope="module")
def system():
    return load_system(SYSTEM)


@pytest.fixture(scope="module")
def table(system, tmp_path_factory):
    """A Kalman table for cart_pair at the sample rate and the file it is saved in (.npz)."""
    path = tmp_path_factory.mktemp("cart") / "cart_kalman.npz"      # the binary container: the node loads it
    t = kalman_table(system, [design_kalman(system, CYC, RATE)])
    t.save(path)
    return t, str(path)


def scenario(system):
    """Sample stamps (ns), channels, the commands ``(stamp_ns, u)`` (off the grid, one on it, one
    before the first sample) and the truth at every sample (exact ZOH of the commands)."""
    base = time.time_ns() - 1000 * 1_000_000_000        # stamps in the past: never 'future_stamp'
    base -= base % 1_000_000
    step = int(1e9 / RATE)
    stamps = [base + k * step for k in range(K)]
    rng = np.random.default_rng(7)
    offs = sorted(set(rng.integers(1, (K - 1) * step, 40).tolist()))
    cmd_ns = [base - 5_000_000] + [base + int(o) for o in offs] + [stamps[100]]
    cmd_ns = sorted(set(cmd_ns))
    cmds = [(s, np.array([rng.uniform(-1.0, 1.0)])) for s in cmd_ns]
    sched = PeriodicSchedule(CYC)
    channels = [sched.channel_at((s - base) * 1e-9) for s in stamps]
    plant = Plant(system, X0, t0=0.0)
    u = cmds[0][1]
    j = 1
    truth = []
    for s in stamps:
        t = (s - base) * 1e-9
        while j < len(cmds) and cmds[j][0] < s:
            plant.advance((cmds[j][0] - base) * 1e-9, u)
            u = cmds[j][1]
            j += 1
        truth.append(plant.advance(t, u))
    return stamps, channels, cmds, np.array(truth)


def offline(system, table, stamps, channels, cmds, truth):
    """The reference: SwitchedObserver with update(..., u=...) at a command on a sample's stamp and
    hold_input for the others, in the pipeline's time (stamp - first sample stamp) * 1e-9."""
    origin = stamps[0]
    obs = SwitchedObserver(system, table, cycles=[CYC], e0=PARAMS["e0"])
    obs.reset(np.zeros(system.n), 0.0)
    before = [u for s, u in cmds if s <= origin]
    obs.hold_input(0.0, before[-1])
    later = [(s, u) for s, u in cmds if s > origin]
    xs, bounds = [], []
    for s, c, x in zip(stamps, channels, truth):
        u_here = None
        while later and later[0][0] <= s:
            cs, cu = later.pop(0)
            if cs == s:
                u_here = cu
            else:
                obs.hold_input((cs - origin) * 1e-9, cu)
        xs.append(obs.update((s - origin) * 1e-9, c, system.C[c - 1] @ x, u=u_here).copy())
        bounds.append(obs.envelope().exact_bound)
    return np.array(xs), np.array(bounds)


def _point(v, stamp_ns):
    from geometry_msgs.msg import PointStamped

    m = PointStamped()
    m.header.stamp = mb.ns_to_stamp(stamp_ns)
    m.header.frame_id = "map"
    m.point.x = float(v)
    return m


@pytest.mark.slow
def test_driven_system_over_dds_matches_the_offline_observer(system, table, tmp_path, ros_node):
    from ros_harness import spin_until
    from std_msgs.msg import Float64MultiArray

    from switchobs_ros import qos
    from switchobs_ros.bag.estimate import estimate, estimator_params
    from tools.launch import NodeProcess, ros_args

    table, table_path = table
    stamps, channels, cmds, truth = scenario(system)
    ref_x, ref_b = offline(system, table, stamps, channels, cmds, truth)
    err_ref = np.linalg.norm(truth - ref_x, axis=1)
    assert err_ref[0] > 0.1 and int((err_ref > ref_b).sum()) == 0

    from nav_msgs.msg import Odometry
    from visualization_msgs.msg import MarkerArray

    state, env, markers = [], [], []
    odom = {"body1": [], "body2": []}
    ros_node.create_subscription(Float64MultiArray, "/estimator/state", state.append, qos.TRUTH)
    ros_node.create_subscription(Float64MultiArray, "/estimator/envelope", env.append, qos.TRUTH)
    ros_node.create_subscription(MarkerArray, "/estimator/markers", markers.append, qos.TRUTH)
    for b, got in odom.items():     # cart_pair's p1, v1 and p2, v2: bodies on a line
        ros_node.create_subscription(Odometry, f"/estimator/{b}/odom", got.append, qos.TRUTH)
    pub_ctl = ros_node.create_publisher(Float64MultiArray, "/estimator/control", qos.CHANNEL_SUB)
    pubs = {1: ros_node.create_publisher(mb.message_class("geometry_msgs/PointStamped"), "left/point", qos.SENSOR),
            2: ros_node.create_publisher(mb.message_class("geometry_msgs/PointStamped"), "right/point", qos.SENSOR)}
    proc = NodeProcess("estimator", ros_args(params={**PARAMS, "gain_table": table_path}),
                       log=tmp_path / "estimator.log")
    try:
        ok = spin_until(ros_node, lambda: pub_ctl.get_subscription_count() > 0
                        and all(p.get_subscription_count() > 0 for p in pubs.values())
                        and ros_node.count_publishers("/estimator/envelope") > 0, 30.0)
        assert ok, proc.output()
        # the commands first (reliable, ahead of the samples they precede), then the samples
        w = mb.LabelledArrayWriter(mb.input_labels(1))
        for s, u in cmds:
            pub_ctl.publish(w.msg(u, s))
            spin_until(ros_node, lambda: False, 0.005)
        spin_until(ros_node, lambda: False, 0.5)
        for s, c, x in zip(stamps, channels, truth):
            pubs[c].publish(_point((system.C[c - 1] @ x)[0], s))
            spin_until(ros_node, lambda: False, 0.004)
        # ~/markers every 10th estimate from the first; its publisher appears right after the first estimate
        # (switchobs_ros.late_markers), so the markers of estimate 0 (and 10 if matched late) are not published
        assert spin_until(ros_node, lambda: len(state) >= K and len(env) >= K and len(odom["body2"]) >= K
                          and len(markers) >= K // 10 - 1, 30.0), (len(state), proc.output())
        # a command for a time already estimated: rejected (old_stamp), counted
        pub_ctl.publish(w.msg(np.array([0.5]), stamps[-2]))
        spin_until(ros_node, lambda: False, 0.5)
    finally:
        rc = proc.stop()
    assert rc == 0, proc.output()
    got = {mb.unpack_labelled(m).stamp_ns: mb.unpack_labelled(m).values for m in state}
    bnd = {mb.unpack_labelled(m).stamp_ns: mb.unpack_labelled(m).values[-1] for m in env}
    assert sorted(got) == stamps, "every sample answered"
    x_live = np.array([got[s] for s in stamps])
    b_live = np.array([bnd[s] for s in stamps])
    scale = np.abs(ref_x).max()
    assert np.abs(x_live - ref_x).max() <= 1e-9 * scale
    np.testing.assert_allclose(b_live, ref_b, rtol=1e-9)
    err = np.linalg.norm(truth - x_live, axis=1)
    assert int((err > b_live).sum()) == 0
    assert err[-1] < 1e-3 * err[0], "converges with the input known"
    # every body on the outputs: odometry (position, velocity) and markers for p1/v1 and p2/v2
    assert "outputs: 2 bodies with odometry and markers: body1 (p1, v1); body2 (p2, v2)" in proc.output()
    for b, (ip, iv) in (("body1", (0, 1)), ("body2", (2, 3))):
        o = {mb.stamp_to_ns(m.header.stamp): m for m in odom[b]}
        assert sorted(o) == stamps
        assert all((o[s].pose.pose.position.x, o[s].twist.twist.linear.x, o[s].pose.pose.position.y)
                   == (got[s][ip], got[s][iv], 0.0) for s in stamps)
    last = markers[-1]
    k = mb.stamp_to_ns(last.markers[0].header.stamp)
    pos = [m for m in last.markers if m.ns == "switchobs/position"]
    assert [(m.pose.position.x, m.pose.position.y) for m in pos] == [(got[k][0], 0.0), (got[k][2], 0.0)]
    # without the commands the same samples are not explained: the input matters here
    free = SwitchedObserver(system, table, cycles=[CYC], e0=PARAMS["e0"])
    free.reset(np.zeros(system.n), 0.0)
    e_free = [np.linalg.norm(x - free.update((s - stamps[0]) * 1e-9, c, system.C[c - 1] @ x))
              for s, c, x in zip(stamps, channels, truth)]
    assert max(e_free[-50:]) > 100 * err[-50:].max()
    assert "rejected ~/control: " in proc.output() and "a command for a time already estimated" in proc.output(), \
        proc.output()[-2000:]

    # the bag tools: the same messages in a bag, the offline pipeline gives the same estimates
    from rclpy.serialization import serialize_message

    from switchobs_ros.bag.io import BagOut, type_name

    bag = tmp_path / "driven"
    out = BagOut(bag, "mcap")
    out.add("/estimator/control", type_name(Float64MultiArray))
    out.add("/left/point", "geometry_msgs/msg/PointStamped")
    out.add("/right/point", "geometry_msgs/msg/PointStamped")
    log = [(s, "/estimator/control", serialize_message(w.msg(u, s))) for s, u in cmds]
    log += [(s, "/left/point" if c == 1 else "/right/point", serialize_message(_point((system.C[c - 1] @ x)[0], s)))
            for s, c, x in zip(stamps, channels, truth)]
    for s, topic, data in sorted(log, key=lambda r: (r[0], r[1] != "/estimator/control")):
        out.write(topic, s, data)
    out.close()
    res = estimate(bag, estimator_params(overrides={**PARAMS, "gain_table": table_path}))
    assert res.accepted["~/control"] == len(cmds) and res.updates == K
    assert np.abs(res.x_hat - ref_x).max() <= 1e-9 * scale
