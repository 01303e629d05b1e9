"""Refusals of bad input by the estimator: values out of range refused at start-up, in params
files and at run time with one line (the node stays up and answers the next valid measurement);
lifecycle transitions that are not valid return FAILURE and the node stays in its state; a
gain-table cache that is not private is refused, a planted table (zero gains, checksum recomputed)
is refused wherever it comes from. Hypothesis over params files, runtime parameter sets and
lifecycle transition sequences."""

from __future__ import annotations

import json
import math
import os
import shutil

import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st
from lifecycle_msgs.msg import State, Transition
from lifecycle_msgs.srv import ChangeState, GetState
from rcl_interfaces.msg import ParameterType, ParameterValue
from rcl_interfaces.srv import SetParameters
from refusals import assert_refused, node_main
from ros_harness import EstimatorIO, spin_until, start_feed
from std_msgs.msg import UInt8
from test_lifecycle import _change, _feed, _set, _state

import msg_bridge as mb
from switchobs_core.table.gains import GainTable
from switchobs_ros.bag.estimate import unanswered
from switchobs_ros.config import PARAMS, RUNTIME_PARAMS, EstimatorConfig, check_runtime_value
from switchobs_ros.core_config import table_cache_path
from switchobs_ros.params import ConfigError
from switchobs_ros.pipeline import EstimatorPipeline
from tools.launch import NodeProcess, ros_args

S = 1_000_000_000


def _planted(src: str, dst) -> str:
    """A copy of the table at ``src`` with every gain zero and the checksum recomputed."""
    data = json.loads(open(src).read())
    data.pop("payload_sha256")
    for d in data["designs"]:
        for ch in d["channels"]:
            ch["L"] = [[0.0] * len(r) for r in ch["L"]]
            ch["L_o"] = [[0.0] * len(r) for r in ch["L_o"]]
    data["payload_sha256"] = GainTable._digest(data)
    with open(dst, "w") as fh:
        json.dump(data, fh)
    return str(dst)


# ------------------------------------------------------------------ start-up
@pytest.mark.parametrize("params, needles", [
    ({"sensor_timeout": 1.0e10}, ("sensor_timeout", "int64")),       # was a 24-line OverflowError
    ({"diagnostics_period": 1.0e12}, ("diagnostics_period", "timer")),
])
def test_start_up_values_out_of_range_are_one_line(params, needles, paper_tables):
    res = node_main("estimator", ros_args(params={"gain_table": paper_tables["periodic"], **params}))
    assert_refused(res, "estimator: error:", *needles, code=2)


@pytest.mark.parametrize("params, needles", [
    ({"rate": 1.0e-12}, ("'rate' x 'time_scale'", "tick timer")),
    ({"rate": 1.0e9}, ("1e+09 Hz",)),
    ({"publish_clock": True, "time_scale": 1.0e300}, ("time_scale",)),
    ({"clock_start": 1.0e300}, ("clock_start", "int32")),
])
def test_camera_sim_numbers_out_of_range_are_one_line(params, needles):
    res = node_main("camera_sim", ros_args(params=params))
    assert_refused(res, "camera_sim: error:", *needles, code=2)


def test_planted_table_is_refused_explicit_or_cached(paper_tables, tmp_path):
    """Zero gains, checksum recomputed: loaded without a word before (open loop, off by 4.8)."""
    planted = _planted(paper_tables["periodic"], tmp_path / "planted.json")
    res = node_main("estimator", ros_args(params={"gain_table": planted}))
    assert_refused(res, "gain_table", "spectral radius", ">= 1", code=2)
    # the same table planted in a world-writable cache folder: refused for the folder, as ssh does
    cache = tmp_path / "cache"
    cache.mkdir()
    os.chmod(cache, 0o777)
    conf = EstimatorConfig.from_values({"gain_table_cache_dir": str(cache)})
    where = table_cache_path(str(cache), conf.system, conf.mode, list(conf.cycles), None, conf["delta"])
    shutil.copy(planted, where)
    res = node_main("estimator", ros_args(params={"gain_table_cache_dir": str(cache)}))
    assert_refused(res, "bad permissions", "gain_table_cache_dir", "writable by group and others",
                   "gain_table_cache_trusted", code=2)


def test_trusted_cache_still_re_verifies_the_table(paper_tables, tmp_path):
    """gain_table_cache_trusted names a shared folder: no permission check, but the planted table
    is not used (re-verified, refused, designed again and re-cached)."""
    cache = tmp_path / "shared"
    cache.mkdir()
    os.chmod(cache, 0o775)
    cfg = {"gain_table_cache_dir": str(cache)}
    conf = EstimatorConfig.from_values(cfg)
    where = table_cache_path(str(cache), conf.system, conf.mode, list(conf.cycles), None, conf["delta"])
    _planted(paper_tables["periodic"], where)
    with pytest.raises(ConfigError, match="writable by the group"):
        EstimatorPipeline.from_params(cfg)
    with pytest.raises(ConfigError, match="not gain_table_cache_dir"):
        EstimatorConfig.from_values({**cfg, "gain_table_cache_trusted": str(tmp_path)})
    pl = EstimatorPipeline.from_params({**cfg, "gain_table_cache_trusted": str(cache)})
    assert any(abs(L).max() > 0 for L in pl.table.designs[0].L)       # designed again, not the planted one
    GainTable.load(where)                                              # and the cache holds the new one


# ------------------------------------------------------------------ params files (hypothesis, in process)
_NUMERIC = [p.name for p in PARAMS if isinstance(p.default, float) and p.name not in ("delta",)
            and not p.name.startswith("schedule.")]
_VALUES = st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.sampled_from(
    [0.0, -1.0, 1e-300, 1e6, 1e10, 1e50, 1e51, 1e150, 1e300, 1.7e308, -1e300]))


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(values=st.dictionaries(st.sampled_from(_NUMERIC + ["initial_estimate", "disturbance.max"]), _VALUES, min_size=1,
                              max_size=4))
@example(values={"consistency.chi2_alpha": 0.5})
def test_params_files_accepted_values_answer_every_valid_measurement(values, paper_tables):
    """Any numbers in a params file: refused with one ConfigError line, or accepted, and then every
    valid measurement (small, or as large as max_abs_value accepts) is answered with a finite
    estimate (nothing accepted silently)."""
    # the samples below are not the model's: the consistency test (on with a declared noise.max)
    # would rightly refuse them (test_consistency.py); here the subject is the ranges of values
    cfg = {"gain_table": paper_tables["periodic"], "consistency.check": "never"}
    for k, v in values.items():
        cfg[k] = (v,) * 12 if k == "initial_estimate" else v
    try:
        pl = EstimatorPipeline.from_params(cfg)
    except ConfigError as err:
        assert "\n" not in str(err) and str(err)
        return
    # likewise the chi-square gate (consistency.chi2_alpha, test_consistency.py): an accepted alpha
    # would rightly refuse these samples as outliers (alpha 0.5: 20 of them, a failure seen at random)
    pl.chi2_alpha = 0.0
    now = 100_000 * S
    pl.on_channel(UInt8(data=1))
    answered = []
    for k in range(20):
        ns = now - 10 * S + k * 50_000_000
        big = 0.5 * pl.max_abs if k % 2 else 1.0         # samples up to the accepted magnitude too
        for part, xy in (("camera", (0.1 * k * big, 0.2)), ("target", (3.0, (1.0 + 0.01 * k) * big))):
            answered += pl.on_pose(part, mb.xy_to_pose(xy, ns, "map"), now)
    answered += pl.flush_all()
    # every pose accepted (valid for this configuration: max_abs_value may reject some) is answered
    assert unanswered(pl) == {}, (values, unanswered(pl))
    assert sum(pl.accepted.values()) + sum(pl.rejected.values()) == 41, values
    assert len(answered) == len({e.stamp_ns for e in answered}) >= pl.accepted["target/pose"], values
    assert all(math.isfinite(v) or v == -1 for e in answered for v in [*e.x_hat, *e.envelope]), values


@settings(max_examples=60, deadline=None)
@given(name=st.sampled_from(sorted(RUNTIME_PARAMS)), value=st.one_of(
    st.floats(allow_nan=True, allow_infinity=True), st.sampled_from([1e-3, 0.01, 1e6, 1e6 + 1, 1e150, 1e151])))
def test_runtime_check_is_the_start_up_check(name, value):
    """One range policy: a runtime value is accepted iff a start-up (params file) with it is."""
    if name.startswith("output."):
        value = int(value) if math.isfinite(value) and abs(value) < 2**62 else -1
    why = check_runtime_value(name, value)
    assert "\n" not in why
    try:
        EstimatorConfig.from_values({name: value})
        started = True
    except ConfigError as err:
        started = False
        assert f"'{name}'" in str(err) and "\n" not in str(err)
    assert started == (why == ""), (name, value, why)


# ------------------------------------------------------------------ runtime parameters over DDS
def _pv(v) -> ParameterValue:
    if isinstance(v, int):
        return ParameterValue(type=ParameterType.PARAMETER_INTEGER, integer_value=v)
    return ParameterValue(type=ParameterType.PARAMETER_DOUBLE, double_value=v)


@pytest.fixture
def live(paper_tables, ros_node, tmp_path):
    """An estimator process, this test's node, its I/O and a set_parameters client."""
    log = tmp_path / "node.log"
    proc = NodeProcess("estimator", ros_args(params={"gain_table": paper_tables["periodic"], "e0": 5.0}), log=log)
    io = EstimatorIO(ros_node)
    assert io.wait_matched()
    client = ros_node.create_client(SetParameters, "/estimator/set_parameters")
    yield proc, ros_node, io, client, log
    proc.stop()


def _answers_next(node, io, n: int = 3) -> bool:
    before = len(io.msgs["state"])
    _feed(io, start_feed(io, 1, n))
    return spin_until(node, lambda: len(io.msgs["state"]) >= before + n, 10.0)


def test_runtime_diagnostics_period_1e12_refused_node_answers(live):
    """set_parameters diagnostics_period 1e12: create_timer raised TypeError and the node died."""
    proc, node, io, client, log = live
    r = _set(node, client, "diagnostics_period", _pv(1.0e12))
    assert not r.successful and "must be in [0.01, 1e+06] s" in r.reason, r.reason
    r = _set(node, client, "sensor_timeout", _pv(1.0e10))
    assert not r.successful and "int64" in r.reason, r.reason
    assert proc.alive() and _answers_next(node, io)


_RUNTIME_VALUES = {
    "sensor_timeout": st.sampled_from([0.5, 1e10, -1.0, math.inf, 1e6]),
    "future_tolerance": st.sampled_from([0.5, 1e300, 0.0, 2.0]),
    "pairing_timeout": st.sampled_from([0.2, 1e12, 1e-9, 0.05]),
    "diagnostics_period": st.sampled_from([1.0, 1e12, 1e-6, 0.5]),
    "max_abs_value": st.sampled_from([1e6, 1e200, 1e3]),
    "output.envelope_every": st.sampled_from([1, 0, 2**62, 7]),
}


@settings(max_examples=6, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(sets=st.lists(st.sampled_from(sorted(_RUNTIME_VALUES)).flatmap(
    lambda n: st.tuples(st.just(n), _RUNTIME_VALUES[n])), min_size=1, max_size=3))
def test_runtime_parameter_sets_node_stays_up_and_answers(live, sets):
    proc, node, io, client, log = live
    for name, value in sets:
        r = _set(node, client, name, _pv(value))
        assert r.successful == (check_runtime_value(name, value) == ""), (name, value, r.reason)
    # back to sane values for the next example, then the node must answer
    for name, value in (("max_abs_value", 1e6), ("future_tolerance", 0.5), ("pairing_timeout", 0.2),
                        ("diagnostics_period", 1.0), ("sensor_timeout", 0.5), ("output.envelope_every", 1)):
        assert _set(node, client, name, _pv(value)).successful
    assert proc.alive() and _answers_next(node, io), sets


# ------------------------------------------------------------------ lifecycle
@pytest.fixture
def managed(paper_tables, ros_node, tmp_path):
    """A managed estimator waiting for the lifecycle services, this test's node and clients."""
    log = tmp_path / "node.log"
    proc = NodeProcess("managed_estimator", ros_args(params={"gain_table": paper_tables["periodic"],
                                                             "autostart": False}), log=log)
    get = ros_node.create_client(GetState, "/estimator/get_state")
    change = ros_node.create_client(ChangeState, "/estimator/change_state")
    yield proc, ros_node, get, change, log
    proc.stop()


def test_invalid_transitions_fail_and_the_node_stays(managed):
    """activate while unconfigured, and two requests at once: FAILURE with the reason (not an
    RCLError traceback and exit 1); the node stays."""
    proc, node, get, change, log = managed
    assert _state(node, get) == State.PRIMARY_STATE_UNCONFIGURED
    assert not _change(node, change, Transition.TRANSITION_ACTIVATE)
    assert _state(node, get) == State.PRIMARY_STATE_UNCONFIGURED and proc.alive()
    # two configure requests at once: one succeeds, the other fails (not valid any more)
    futs = [change.call_async(ChangeState.Request(transition=Transition(id=Transition.TRANSITION_CONFIGURE)))
            for _ in range(2)]
    assert spin_until(node, lambda: all(f.done() for f in futs), 30.0)
    assert sorted(f.result().success for f in futs) == [False, True]
    assert _state(node, get) == State.PRIMARY_STATE_INACTIVE and proc.alive()
    assert _change(node, change, Transition.TRANSITION_CLEANUP)
    text = log.read_text()
    assert "transition 'activate' is not valid in state 'unconfigured'" in text, text
    assert "Traceback" not in text


_TRANSITIONS = [Transition.TRANSITION_CONFIGURE, Transition.TRANSITION_CLEANUP, Transition.TRANSITION_ACTIVATE,
                Transition.TRANSITION_DEACTIVATE, 99]
_GOAL = {State.PRIMARY_STATE_UNCONFIGURED: {Transition.TRANSITION_CONFIGURE: State.PRIMARY_STATE_INACTIVE},
         State.PRIMARY_STATE_INACTIVE: {Transition.TRANSITION_CLEANUP: State.PRIMARY_STATE_UNCONFIGURED,
                                        Transition.TRANSITION_ACTIVATE: State.PRIMARY_STATE_ACTIVE},
         State.PRIMARY_STATE_ACTIVE: {Transition.TRANSITION_DEACTIVATE: State.PRIMARY_STATE_INACTIVE}}


@settings(max_examples=5, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(seq=st.lists(st.sampled_from(_TRANSITIONS), min_size=1, max_size=6))
def test_lifecycle_sequences_node_alive_and_answering(managed, seq):
    """Any sequence of transitions (valid or not, and an unknown id): each valid one succeeds and
    moves as the lifecycle says, each other one fails and the node stays; after the sequence the
    node is alive, answers get_state, and once active answers the next valid measurement."""
    proc, node, get, change, log = managed
    state = _state(node, get)
    for tid in seq:
        goal = _GOAL.get(state, {}).get(tid)
        assert _change(node, change, tid) == (goal is not None), (state, tid)
        state = goal if goal is not None else state
        assert _state(node, get) == state and proc.alive()
    if state == State.PRIMARY_STATE_UNCONFIGURED:
        assert _change(node, change, Transition.TRANSITION_CONFIGURE)
        state = State.PRIMARY_STATE_INACTIVE
    if state == State.PRIMARY_STATE_INACTIVE:
        assert _change(node, change, Transition.TRANSITION_ACTIVATE)
    io = EstimatorIO(node)
    assert io.wait_matched()
    assert _answers_next(node, io)
    for s in io.subs + [io.sub_cov]:
        node.destroy_subscription(s)
    for p in (io.pub_channel, io.pub_camera, io.pub_target):
        node.destroy_publisher(p)
    node.destroy_client(io.reset_client)
