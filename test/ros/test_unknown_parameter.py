"""A misspelled parameter gets the node's own line, naming it, the closest known name and the
known ones: at start-up (test_startup_failures.py) and at run time over DDS, through the
``set_parameters`` and ``set_parameters_atomically`` services (rclpy's own answer was
``Invalid access to undeclared parameter(s): []``)."""

from __future__ import annotations

import pytest
from rcl_interfaces.msg import Parameter as ParamMsg
from rcl_interfaces.srv import GetParameters, SetParametersAtomically
from test_lifecycle import _call, _set
from test_refusals_node import _answers_next, _pv, live  # noqa: F401  (live: the fixture)

from switchobs_ros.config import PARAMS
from switchobs_ros.params import unknown_parameters

KNOWN = ", ".join(sorted(p.name for p in PARAMS))


def test_unknown_parameters_message():
    assert unknown_parameters(["sensor_timeout", "use_sim_time", "qos_overrides./x.depth"], PARAMS, "estimator") == ""
    assert unknown_parameters(["sensor_timeot"], PARAMS, "estimator") == (
        "unknown parameter sensor_timeot for node 'estimator' ('sensor_timeot': did you mean 'sensor_timeout'?) "
        f"(known: {KNOWN})")
    # a name that differs in case only is that name (difflib alone suggested schedule.s for schedule.H)
    assert "('schedule.H': did you mean 'schedule.h'?)" in unknown_parameters(["schedule.H"], PARAMS, "estimator")
    assert "('E0': did you mean 'e0'?)" in unknown_parameters(["E0"], PARAMS, "estimator")
    # no close name: no guess; several: all named, sorted, once
    assert unknown_parameters(["zzz", "abc", "zzz"], PARAMS, "n") == (
        f"unknown parameters abc, zzz for node 'n' (known: {KNOWN})")


def test_runtime_misspelled_parameter_gets_the_nodes_line(live):  # noqa: F811
    proc, node, io, client, log = live
    r = _set(node, client, "sensor_timeot", _pv(1.0))
    assert not r.successful
    assert r.reason.startswith("unknown parameter sensor_timeot for node 'estimator' "
                               "('sensor_timeot': did you mean 'sensor_timeout'?) (known: "), r.reason
    assert "Invalid access" not in r.reason
    atomic = node.create_client(SetParametersAtomically, "/estimator/set_parameters_atomically")
    res = _call(node, atomic, SetParametersAtomically.Request(parameters=[
        ParamMsg(name="sensor_timeout", value=_pv(2.0)), ParamMsg(name="output.envelope_evry", value=_pv(2))]))
    assert not res.result.successful and "unknown parameter output.envelope_evry" in res.result.reason
    assert "did you mean 'output.envelope_every'" in res.result.reason
    # all or nothing: sensor_timeout kept its value; a known name still works; the node answers
    get = node.create_client(GetParameters, "/estimator/get_parameters")
    assert _call(node, get, GetParameters.Request(names=["sensor_timeout"])).values[0].double_value == 0.5
    assert _set(node, client, "sensor_timeout", _pv(0.7)).successful
    assert proc.alive() and _answers_next(node, io)


def test_wrong_type_names_the_value_and_hints_only_when_it_helps(ros_node):
    """``-p e0:=abc`` names the value and its type and gives no decimal-point hint (that hint is
    for an integer where a float is expected, which is converted anyway)."""
    from rclpy.node import Node
    from rclpy.parameter import Parameter

    from switchobs_ros.params import ConfigError, declare_all

    node = Node("wrong_type", context=ros_node.context,
                parameter_overrides=[Parameter("e0", value="abc")])
    try:
        with pytest.raises(ConfigError) as err:
            declare_all(node, [p for p in PARAMS if p.name == "e0"])
    finally:
        node.destroy_node()
    assert str(err.value) == "parameter 'e0' must be a double (got 'abc', string)"


def test_a_number_list_mixing_integers_and_decimals_is_read_as_doubles(tmp_path):
    """rcl refuses ``h: [1, 0.8, 0.8]`` (``Sequence should be of same type``); the nodes read it as doubles,
    from a params file (a corrected copy; the rest of the text, e.g. rcl's ``1.0e6``, as written) and from
    ``-p``."""
    import rclpy
    from rclpy.context import Context

    from switchobs_ros.ros_args import with_float_lists

    f = tmp_path / "p.yaml"
    f.write_text("estimator:\n  ros__parameters:\n    max_abs_value: 1.0e6\n    schedule:\n"
                 "      h: [1, 0.8, 0.8]   # three channels\n      tau: [2, 3]\n")
    for args in (["x", "--ros-args", "--params-file", str(f)], ["x", "--ros-args", "-p", "schedule.h:=[1, 0.8, 0.8]",
                                                                 "-p", "schedule.tau:=[2, 3]",
                                                                 "-p", "max_abs_value:=1.0e6"]):
        ctx = Context()
        with pytest.raises(Exception, match="Sequence should be of same type"):
            rclpy.init(args=args, context=ctx)          # rcl's own reading
        ctx = Context()
        fixed = with_float_lists(args)
        rclpy.init(args=fixed, context=ctx)
        try:
            node = rclpy.create_node("estimator", context=ctx, automatically_declare_parameters_from_overrides=True)
            assert node.get_parameter("schedule.h").value == [1.0, 0.8, 0.8]
            assert node.get_parameter("schedule.tau").value == [2, 3], "a list of integers alone: as written"
            assert node.get_parameter("max_abs_value").value == 1.0e6
            node.destroy_node()
        finally:
            rclpy.shutdown(context=ctx)
    assert fixed[-3:] == ["schedule.tau:=[2, 3]", "-p", "max_abs_value:=1.0e6"]


@pytest.mark.parametrize("value,expected", [(0.2, (0.2,)), (1, (1.0,)), ([0.1, 0.2], (0.1, 0.2)), (None, ())])
def test_disturbance_max_takes_one_number_or_a_list(ros_node, value, expected):
    """``-p disturbance.max:=0.2`` (a double, or an integer) is the one-entry list; a list stays a
    list; unset is empty (the system's own declaration); the params-file reader does the same."""
    from rclpy.node import Node
    from rclpy.parameter import Parameter

    from switchobs_ros.config import params_from_file
    from switchobs_ros.params import declare_all

    over = [] if value is None else [Parameter("disturbance.max", value=value)]
    node = Node("disturbance_max", context=ros_node.context, parameter_overrides=over)
    try:
        got = declare_all(node, [p for p in PARAMS if p.name == "disturbance.max"])
    finally:
        node.destroy_node()
    assert got["disturbance.max"] == expected
    if value is not None:
        assert params_from_file(overrides={"disturbance.max": value})["disturbance.max"] == expected
