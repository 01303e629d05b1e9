"""A command that arrives after samples it governs were answered: rejected (never applied late)
and, since the plant did follow it, the bounds withdrawn unless it repeats the input already held;
in-process through the bag tools (the file order is the arrival order). The samples between its
stamp and its arrival were answered without it (the consistency test may already withdraw the
bounds there); from its arrival on no bound is published."""

from __future__ import annotations

import numpy as np
import pytest
from rclpy.serialization import serialize_message
from std_msgs.msg import Float64MultiArray
from test_control_input import PARAMS, _point, scenario
from test_control_input import system as system
from test_control_input import table as table

import msg_bridge as mb
from switchobs_ros.bag.estimate import estimate, estimator_params
from switchobs_ros.bag.io import BagOut, type_name

LATE = 20       # the command moved behind the samples of the next 0.2 s


def _bag(path, system, stamps, channels, cmds, truth, late: int | None):
    """Commands and samples in stamp order, except command ``late`` written 10 samples after its stamp."""
    w = mb.LabelledArrayWriter(mb.input_labels(1))
    out = BagOut(path, "mcap")
    out.add("/estimator/control", type_name(Float64MultiArray))
    out.add("/left/point", "geometry_msgs/msg/PointStamped")
    out.add("/right/point", "geometry_msgs/msg/PointStamped")
    step = stamps[1] - stamps[0]
    log = [(s + (10 * step if i == late else 0), 0 if i != late else 1, "/estimator/control",
            serialize_message(w.msg(u, s))) for i, (s, u) in enumerate(cmds)]
    log += [(s, 0, "/left/point" if c == 1 else "/right/point", serialize_message(_point((system.C[c - 1] @ x)[0], s)))
            for s, c, x in zip(stamps, channels, truth)]
    for s, _order, topic, data in sorted(log, key=lambda r: (r[0], r[1], r[2] != "/estimator/control")):
        out.write(topic, s, data)
    out.close()
    return path


@pytest.mark.parametrize("repeat", [False, True])
def test_a_late_command_withdraws_the_bounds_unless_it_repeats_the_held_input(system, table, tmp_path, repeat):
    stamps, channels, cmds, truth = scenario(system)
    if repeat:      # a late command that repeats the input held at its stamp: the plant's input did not change
        cmds.insert(LATE, ((cmds[LATE - 1][0] + cmds[LATE][0]) // 2, cmds[LATE - 1][1].copy()))
    bag = _bag(tmp_path / "late", system, stamps, channels, cmds, truth, LATE)
    res = estimate(bag, estimator_params(overrides={**PARAMS, "gain_table": table[1]}))
    assert res.rejected.get("~/control old_stamp", 0) == 1, res.rejected
    after = res.stamps > cmds[LATE][0] + 10 * (stamps[1] - stamps[0])
    exact = res.envelope[:, -1]
    if repeat:
        assert res.bound_valid
        err = np.linalg.norm(truth - res.x_hat, axis=1)
        assert int((err > exact).sum()) == 0
    else:
        assert not res.bound_valid
        assert "another input than the plant's" in res.bound_invalid_why
        assert np.all(exact[after] == -1.0)     # no bound published once the command is known
        assert np.all(exact[res.stamps < cmds[LATE][0]] > 0.0)    # the samples before its stamp are unaffected
