"""Fixed frame transforms (switchobs_core.model.frames): points, orientations, pose covariances,
the two written forms (yaw pitch roll as static_transform_publisher, and a unit quaternion)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from switchobs_core.model.frames import parse_transform

YAW = 0.7
ODOM = f"odom 2.0 -1.0 0.5 {YAW} 0 0"


def test_transform_numbers():
    tf = parse_transform(ODOM)
    c, s = math.cos(YAW), math.sin(YAW)
    np.testing.assert_allclose(tf.R, [[c, -s, 0], [s, c, 0], [0, 0, 1]], atol=1e-15)
    np.testing.assert_allclose(tf.point([1.0, 0.0, 0.0]), [2.0 + c, -1.0 + s, 0.5], atol=1e-15)
    # the same rotation as a quaternion; ':' after the frame is accepted
    q = parse_transform(f"odom: 2 -1 0.5 0 0 {math.sin(YAW / 2)!r} {math.cos(YAW / 2)!r}")
    np.testing.assert_allclose(q.R, tf.R, atol=1e-15)
    # an orientation: yaw adds
    np.testing.assert_allclose(tf.orientation([0, 0, math.sin(0.1), math.cos(0.1)]),
                               [0, 0, math.sin(YAW / 2 + 0.1), math.cos(YAW / 2 + 0.1)], atol=1e-15)
    # a pose covariance: R S R' on the position and on the rotation block
    S = np.diag([4.0, 1.0, 9.0, 0.1, 0.2, 0.3])
    Sw = tf.pose_covariance(S)
    np.testing.assert_allclose(Sw[:2, :2], tf.R[:2, :2] @ np.diag([4.0, 1.0]) @ tf.R[:2, :2].T, atol=1e-15)
    assert Sw[2, 2] == 9.0 and Sw[5, 5] == pytest.approx(0.3)
    # yaw pitch roll as static_transform_publisher: roll about x first
    r = parse_transform("cam 0 0 0 0 0 1.5707963267948966")
    np.testing.assert_allclose(r.point([0, 1, 0]), [0, 0, 1], atol=1e-15)
