"""Refusals of bad input by the tools and the estimator: huge input specifications, topic names ROS
refuses, binary tables whose members lie, bags with nothing to estimate, channels no source feeds,
recorded stamps that are no time. Every refusal is one line and a non-zero exit within 30 s and
4 GB of address space (test/ros/refusals.py); an accepted input keeps the good data."""

from __future__ import annotations

import time

import pytest
import yaml
from refusals import assert_refused, run, switchobs_bag

from tools.launch import ros_args


@pytest.fixture(scope="module")
def bag(tmp_path_factory):
    """A small input bag (2 s at 20 Hz)."""
    out = tmp_path_factory.mktemp("bags") / "in"
    res = switchobs_bag("generate", out, "--duration", "2", "--rate", "20")
    assert res.returncode == 0, res.stderr
    return out


def _inputs_file(path, section) -> str:
    path.write_text(yaml.safe_dump({"inputs": section}, default_flow_style=True, width=1 << 30))
    return str(path)


def _label(k: int) -> str:
    digits = "abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ"
    return "".join(digits[(k // 52 ** i) % 52] for i in range(3))


# ------------------------------------------------------------------ input specifications
@pytest.mark.parametrize("case, needle", [
    ("labels_100k", "100000 fields; at most 4096"),
    ("sources_9k", "9000 sources; the system's channels have 8 rows in all, so at most 8 sources"),
])
def test_huge_specifications_are_one_line_in_the_tool_and_the_node(case, needle, bag, tmp_path, paper_tables):
    """A 0.9 MB specification (100 000 labels and rows in one labelled array; 9 000 sources) ran
    past 30 s in the bag tool, and the estimator ignored SIGTERM while checking it (a quadratic
    count). Now both refuse it in one line; what time they take is reading the YAML."""
    if case == "labels_100k":
        section = {"channel_topic": "camera/active_channel", "sources": [
            {"topic": "t", "type": "std_msgs/Float64MultiArray", "fields": [_label(k) for k in range(100_000)],
             "rows": [0] * 100_000}]}
    else:
        section = {"channel_topic": "camera/active_channel", "sources": [
            {"topic": f"s{k}", "type": "geometry_msgs/PoseStamped", "fields": ["pose.position.x"], "rows": [0]}
            for k in range(9_000)]}
    spec = _inputs_file(tmp_path / "inputs.yaml", section)
    assert (tmp_path / "inputs.yaml").stat().st_size < 1 << 20
    t0 = time.monotonic()
    res = switchobs_bag("estimate", bag, "--csv", tmp_path / "e.csv", "--gain-table", paper_tables["periodic"],
                        "-p", f"inputs:={spec}")
    assert_refused(res, needle, code=2)
    assert time.monotonic() - t0 < 15
    res = run("switchobs_ros.estimator", *ros_args(params={"gain_table": paper_tables["periodic"], "inputs": spec}))
    assert_refused(res, "estimator: error:", needle, code=2)


def test_a_topic_name_ros_refuses_is_refused_at_start_up(paper_tables, tmp_path):
    """A 5 000-character topic name passed the specification's check, then create_subscription
    raised InvalidTopicNameException (35 lines)."""
    spec = _inputs_file(tmp_path / "inputs.yaml", {"channel_topic": "c" * 5000, "sources": [
        {"topic": "camera/pose", "type": "geometry_msgs/PoseStamped", "fields": ["pose.position.x", "pose.position.y"],
         "rows": ["camera.p_x", "camera.p_y"]},
        {"topic": "target/pose", "type": "geometry_msgs/PoseStamped", "fields": ["pose.position.x", "pose.position.y"],
         "rows": [2, 3]}]})
    res = run("switchobs_ros.estimator", *ros_args(params={"gain_table": paper_tables["periodic"], "inputs": spec}))
    assert_refused(res, "estimator: error:", "channel_topic", "(5000 characters) is not a valid topic name",
                   "topic length should not exceed", code=2)


# ------------------------------------------------------------------ binary gain tables
@pytest.fixture(scope="module")
def lying_table(tmp_path_factory):
    """A Kalman table of the paper's system (.npz) whose error transition's .npy header claims
    2^33 doubles (64 GiB), in a DEFLATE member."""
    from _binary_tables import lying_member

    from switchobs_core.design.kalman import design_kalman
    from switchobs_core.model.scenarios import paper_system
    from switchobs_core.model.schedule import Cycle
    from switchobs_core.table.gains import kalman_table

    d = tmp_path_factory.mktemp("tables")
    sys_ = paper_system()
    saved = kalman_table(sys_, [design_kalman(sys_, Cycle.from_ts(2.0, 0.6), 20.0)]).save(d / "k.npz")
    bad = d / "lying.npz"
    bad.write_bytes(lying_member(saved, "k0_E.npy"))
    return bad


def test_a_binary_table_whose_member_lies_is_one_line_everywhere(lying_table, bag, tmp_path):
    """`switchobs show`, `switchobs_bag estimate --gain-table` and the estimator's start-up died
    with a 26-line traceback (Unable to allocate 64.0 GiB)."""
    from refusals import switchobs

    needles = ("not a complete binary gain table", "k0_E: its .npy header claims 68719476736 bytes")
    assert_refused(switchobs("show", lying_table), *needles, code=2)
    res = switchobs_bag("estimate", bag, "--csv", tmp_path / "e.csv", "--gain-table", lying_table)
    assert_refused(res, *needles, code=2)
    res = run("switchobs_ros.estimator", *ros_args(params={"gain_table": str(lying_table)}))
    assert_refused(res, "estimator: error:", "gain_table", *needles, code=2)
