"""Input frames: fixed transforms declared in ``input_transforms`` map a pose given in another frame
into the estimator's before it is checked and used; a frame with no transform is rejected
(``wrong_frame``) with a message naming the parameter; bad declarations stop start-up with one line."""

from __future__ import annotations

import time

import numpy as np
import pytest
from std_msgs.msg import UInt8

import msg_bridge as mb
from switchobs_core.exceptions import InvalidArgument
from switchobs_core.model.frames import parse_transform, parse_transforms
from switchobs_ros.config import params_from_file
from switchobs_ros.params import ConfigError
from switchobs_ros.pipeline import EstimatorPipeline

YAW = 0.7
ODOM = f"odom 2.0 -1.0 0.5 {YAW} 0 0"       # odom -> map: turned by YAW about z, shifted


@pytest.mark.parametrize("entries, match", [
    (["odom 1 2 3"], "3 numbers; expected '<frame> x y z yaw pitch roll' or '<frame> x y z qx qy qz qw'"),
    (["odom 1 2 3 a b c"], "must be numbers"),
    (["odom 0 0 0 0 0 0 2"], r"the quaternion \(qx, qy, qz, qw\) has norm 2; give a unit one"),
    (["odom 0 0 0 0 0 nan"], "every number must be finite"),
    (["odom 0 0 0 0 0 0", "odom 1 0 0 0 0 0"], "frame 'odom' is given twice"),
    (["map 0 0 0 0 0 0"], "frame 'map' is the estimator's own frame"),
    (["1odom 0 0 0 0 0 0"], "expected"),
])
def test_bad_declarations_are_one_line(entries, match):
    with pytest.raises(InvalidArgument, match=match):
        parse_transforms(entries, "map")
    with pytest.raises(ConfigError, match=r"^parameter 'input_transforms': .*" + match) as err:
        EstimatorPipeline.from_params(params_from_file(overrides={"input_transforms": entries}))
    assert "\n" not in str(err.value)


def _run(table, frame, transforms, poses):
    pl = EstimatorPipeline.from_params(params_from_file(overrides={
        "gain_table": table, "reorder_window_ms": 0.0, "input_transforms": transforms}))
    pl.on_channel(UInt8(data=1))
    out = []
    now = time.time_ns()
    for s, cam, tgt in poses:
        out += pl.on_pose("camera", mb.xy_to_pose(cam, s, frame), now)
        out += pl.on_pose("target", mb.xy_to_pose(tgt, s, frame), now)
    out += pl.flush_all()
    return pl, out


def test_a_pose_in_a_declared_frame_is_mapped_and_used(paper_tables):
    tf = parse_transform(ODOM)
    base = time.time_ns() - 10_000_000_000
    rng = np.random.default_rng(2)
    world = [(base + k * 10_000_000, rng.normal(size=2), 3.0 + rng.normal(size=2)) for k in range(50)]
    # the same positions given in odom
    inv = tf.R.T

    def to_odom(p):
        return (inv @ (np.array([p[0], p[1], 0.0]) - tf.t))

    odom = [(s, to_odom(c), to_odom(t)) for s, c, t in world]
    ref_pl, ref = _run(paper_tables["periodic"], "map", [], world)
    pl, got = _run(paper_tables["periodic"], "odom", [ODOM], [(s, c[:2], t[:2]) for s, c, t in odom])
    # the poses built from odom's x, y only (z of the pose 0): compare with the map-frame run of those
    assert len(got) == len(ref) == 50 and not pl.rejected and not ref_pl.rejected
    mapped = [(s, (tf.R @ np.array([c[0], c[1], 0.0]) + tf.t)[:2], (tf.R @ np.array([t[0], t[1], 0.0]) + tf.t)[:2])
              for s, c, t in odom]
    _, ref2 = _run(paper_tables["periodic"], "map", [], mapped)
    for a, b in zip(got, ref2):
        assert a.stamp_ns == b.stamp_ns
        np.testing.assert_array_equal(a.x_hat, b.x_hat)
    # and the map-frame run of the original positions agrees to the mapping's rounding
    assert max(np.abs(a.x_hat - b.x_hat).max() for a, b in zip(got, ref)) < 1e-12 * 10


def test_a_frame_without_transform_is_rejected_naming_the_parameter(paper_tables):
    pl, got = _run(paper_tables["periodic"], "base_link", [ODOM], [(time.time_ns() - 10**9, (0.0, 0.0), (3.0, 1.0))])
    assert got == [] and pl.rejected[("camera/pose", "wrong_frame")] == 1
    assert pl.last_rejection == ("target/pose: wrong_frame: header.frame_id: 'base_link' (expected 'map'): declare "
                                 "the frame's fixed transform in parameter input_transforms ('<frame> x y z yaw "
                                 "pitch roll'), or publish in input_frame_id")


def test_the_node_declares_the_parameter(paper_tables, ros_node):
    from rclpy.parameter import Parameter

    from switchobs_ros.estimator import EstimatorNode

    est = EstimatorNode(parameter_overrides=[Parameter("gain_table", value=paper_tables["periodic"]),
                                             Parameter("input_transforms", value=[ODOM, "cam 0 0 1 0 0 0 1"])])
    try:
        assert sorted(est.pipeline.transforms) == ["cam", "odom"]
        np.testing.assert_array_equal(est.pipeline.transforms["odom"].t, [2.0, -1.0, 0.5])
    finally:
        est.destroy_node()
