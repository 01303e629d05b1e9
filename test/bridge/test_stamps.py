"""msg_bridge.stamps owns "a header stamp is a valid time": every layer that reads a stamp
(check_time, check_pose, FieldReader, the labelled array's two doubles) accepts and rejects the
same ``(sec, nanosec)`` pairs as :func:`msg_bridge.stamps.time_ns`, and takes the same
nanoseconds from those it accepts."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import msg_bridge as mb
from msg_bridge import Reason
from msg_bridge.convert import labelled_stamp_ns
from msg_bridge.stamps import MAX_SEC, NS_PER_S, float_time_ns, time_ns, valid_time

# around each edge of the rule (0, NS_PER_S) and of int32 / uint32, plus anything in between
_edges = [-(2**31), -1, 0, 1, NS_PER_S - 1, NS_PER_S, NS_PER_S + 1, 2**31 - 1, 2**32 - 1]
_ints = st.one_of(st.sampled_from(_edges), st.integers(-(2**32), 2**32))
_POSE = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0)


def test_rule_edges():
    assert NS_PER_S == 10**9
    assert time_ns(0, 0) == 0 and time_ns(3, NS_PER_S - 1) == 4 * NS_PER_S - 1
    assert time_ns(-1, 0) is None and time_ns(0, NS_PER_S) is None and time_ns(0, -1) is None
    assert float_time_ns(2.0, 5.0) == 2 * NS_PER_S + 5
    for bad in ((math.nan, 0.0), (0.0, math.inf), (-math.inf, 0.0), (1.5, 0.0), (0.0, 0.5),
                (9223372036.0, 999999999.0), (2.0**31, 0.0)):      # whole, but beyond a header's int32 sec
        assert float_time_ns(*bad) is None, bad
    assert float_time_ns(2.0**31 - 1, 999999999.0) == (2**31 - 1) * NS_PER_S + 999999999 < 2**63


@settings(max_examples=400, deadline=None)
@given(_ints, _ints)
def test_every_path_applies_the_one_rule(sec, nsec):
    ns = time_ns(sec, nsec)
    assert (ns is None) == (not (sec >= 0 and 0 <= nsec < NS_PER_S))
    assert ns is None or ns == sec * NS_PER_S + nsec

    rej = mb.check_time(sec, nsec)
    assert (rej is None) == (ns is not None)
    if rej is not None:
        assert rej.reason is Reason.BAD_STAMP and rej.field == "header.stamp"
        assert rej.detail == f"sec {sec}, nanosec {nsec} is not a valid time (sec >= 0, nanosec < 1e9)"

    pose = mb.check_pose((sec, nsec, "map", _POSE))
    assert (pose is not None and pose.reason is Reason.BAD_STAMP) == (ns is None)
    if ns is None:
        assert pose == rej

    msg = SimpleNamespace(header=SimpleNamespace(stamp=SimpleNamespace(sec=sec, nanosec=nsec), frame_id="map"),
                          pose=SimpleNamespace(position=SimpleNamespace(x=1.5)))
    reader = mb.FieldReader("geometry_msgs/msg/PoseStamped", ["pose.position.x"])
    if ns is None:
        with pytest.raises(mb.BridgeError) as err:
            reader.read(msg)
        assert err.value.rejection == rej
    else:
        got, frame, y = reader.read(msg)
        assert (got, frame, list(y)) == (ns, "map", [1.5])

    # the labelled array's doubles: the same rule once they are whole numbers (these ints are exact), and
    # at most a header's int32 sec (a header's own type bounds it on the paths above)
    if ns is None or sec > MAX_SEC:
        with pytest.raises(mb.BridgeError, match="is not a valid time"):
            labelled_stamp_ns(float(sec), float(nsec))
    else:
        assert labelled_stamp_ns(float(sec), float(nsec)) == ns


@pytest.mark.parametrize("kind", [np.int32, np.int64, np.uint32, int])
def test_numpy_integers_neither_wrap_nor_raise(kind):
    """A stamp's integers given as numpy scalars (a direct caller's): the same nanoseconds as Python ints,
    no int32 wrap (5 s is 5e9 ns, beyond an int32), no OverflowError, the same decision."""
    sec, nsec = kind(5), kind(7)
    assert time_ns(sec, nsec) == 5 * NS_PER_S + 7 and type(time_ns(sec, nsec)) is int
    assert valid_time(sec, nsec) and mb.check_time(sec, nsec) is None
    assert mb.check_time(5, kind(7)) is None and mb.check_time(kind(5), NS_PER_S) is not None

