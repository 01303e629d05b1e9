"""Params files under namespaces: the shipped files apply to a node in any namespace (a fleet of
robots, one estimator each), a file that applies to no section of the node is refused at start-up
naming the file and the node, and body frame ids carry the robot's prefix."""

from __future__ import annotations

from pathlib import Path

import pytest
import rclpy
import yaml
from rclpy.context import Context
from rclpy.node import Node

from switchobs_ros import params_files
from switchobs_ros.config import body_frame_prefix, params_from_file
from switchobs_ros.estimator import EstimatorNode
from switchobs_ros.params import ConfigError

REPO = Path(__file__).resolve().parents[2]
SHIPPED = sorted((REPO / "config").glob("*.yaml"))


def _params_file_of(path: Path) -> bool:
    doc = yaml.safe_load(path.read_text())
    return isinstance(doc, dict) and any(isinstance(v, dict) and "ros__parameters" in v for v in doc.values())


@pytest.mark.parametrize("path", [p for p in SHIPPED if _params_file_of(p)], ids=lambda p: p.name)
def test_every_shipped_params_file_applies_in_any_namespace(path):
    doc = yaml.safe_load(path.read_text())
    for fqn in ("/estimator", "/robot1/estimator", "/fleet/robot2/camera_sim"):
        assert params_files.matching_sections(doc, fqn), (path.name, fqn)


@pytest.mark.parametrize("key", ["estimator", "/estimator", "/**", "/**/estimator", "/*/estimator", "robot1/estimator",
                                 "/robot2/estimator", "camera_sim", "/**/camera_sim", "/robot1/*"])
@pytest.mark.parametrize("ns", ["/", "/robot1", "/fleet/robot1"])
def test_section_matching_is_rclpy_own(tmp_path, key, ns):
    """key_matches gives a node exactly the sections rclpy gives it."""
    f = tmp_path / "p.yaml"
    f.write_text(yaml.safe_dump({key: {"ros__parameters": {"probe": 3}}}))
    ctx = Context()
    rclpy.init(args=["x", "--ros-args", "--params-file", str(f)], context=ctx)
    try:
        node = Node("estimator", namespace=ns, context=ctx)
        got = "probe" in node._parameter_overrides
        fqn = node.get_fully_qualified_name()
        node.destroy_node()
    finally:
        rclpy.try_shutdown(context=ctx)
    assert params_files.key_matches(key, fqn) == got, (key, fqn)


def test_a_file_keyed_for_the_root_is_refused_under_a_namespace(tmp_path):
    f = tmp_path / "old.yaml"
    f.write_text("estimator:\n  ros__parameters:\n    e0: 5.0\n")
    why = params_files.unmatched_files([f], "/robot1/estimator")
    assert str(f) in why and "'/robot1/estimator'" in why and "'estimator'" in why and "/**" in why
    assert params_files.unmatched_files([f], "/estimator") == ""
    with pytest.raises(ConfigError, match="no section for node '/estimator'"):
        params_from_file([REPO / "config" / "cart_pair.yaml"])      # a system file, not a params file


def test_params_files_are_read_from_the_ros_arguments():
    argv = ["estimator", "--params-file", "not-ros.yaml", "--ros-args", "--params-file", "a.yaml", "-p", "e0:=2.0",
            "--params-file", "b.yaml", "--", "--params-file", "c.yaml"]
    assert params_files.params_files(argv) == ["a.yaml", "b.yaml"]


@pytest.mark.parametrize("value,ns,prefix", [("auto", "/", ""), ("auto", "/robot1", "robot1/"),
                                             ("auto", "/fleet/robot2", "fleet/robot2/"), ("", "/robot1", ""),
                                             ("r1/", "/robot1", "r1/")])
def test_body_frame_prefix(value, ns, prefix):
    assert body_frame_prefix(value, ns) == prefix


@pytest.fixture
def fleet_context(paper_tables, monkeypatch):
    """A context whose ROS arguments are the shipped config/estimator.yaml (and a prepared table)."""
    shipped = str(REPO / "config" / "estimator.yaml")
    monkeypatch.setattr(params_files, "GLOBAL_FILES", [shipped])
    ctx = Context()
    rclpy.init(args=["estimator", "--ros-args", "--params-file", shipped, "-p",
                     f"gain_table:={paper_tables['periodic']}"], context=ctx)
    yield ctx
    rclpy.try_shutdown(context=ctx)


def test_two_robots_take_the_shipped_file(fleet_context):
    shipped = params_from_file([REPO / "config" / "estimator.yaml"])
    nodes = [EstimatorNode(namespace=ns, context=fleet_context) for ns in ("/robot1", "/robot2")]
    try:
        for node, robot in zip(nodes, ("robot1", "robot2")):
            assert node.get_fully_qualified_name() == f"/{robot}/estimator"
            for name in ("e0", "schedule.tau", "schedule.s", "reorder_window_ms", "consistency.check", "noise.max"):
                assert node.cfg[name] == shipped[name], (robot, name)
            assert node.observer.e0 == shipped["e0"] == 5.0      # the file's, not the code's default (1.0)
            assert node.child_frames == [f"{robot}/camera", f"{robot}/agent1", f"{robot}/agent2"]
    finally:
        for node in nodes:
            node.destroy_node()


def test_an_estimator_given_a_file_for_another_name_refuses_to_start(tmp_path, monkeypatch, paper_tables):
    f = tmp_path / "old.yaml"
    f.write_text("estimator:\n  ros__parameters:\n    e0: 5.0\n")
    monkeypatch.setattr(params_files, "GLOBAL_FILES", [str(f)])
    ctx = Context()
    rclpy.init(args=["estimator", "--ros-args", "--params-file", str(f)], context=ctx)
    try:
        with pytest.raises(ConfigError, match=r"old\.yaml .*no section for node '/robot1/estimator'"):
            EstimatorNode(namespace="/robot1", context=ctx)
    finally:
        rclpy.try_shutdown(context=ctx)


@pytest.mark.parametrize("name,table", [("estimator.yaml", "periodic"), ("estimator_sequence.yaml", "sequence"),
                                        ("robot_template.yaml", "periodic")])
def test_every_shipped_estimator_config_tests_its_bound(paper_tables, name, table):
    """No shipped configuration publishes a bound that nothing checks: the consistency test is on;
    the files for camera_sim's noise-free data declare it (noise.max 0: a sample the bound cannot
    explain is rejected), the robot template, whose noise is the user's, holds samples to the
    noise-free bound until it declares one (watch only: such a sample withdraws the bounds)."""
    from switchobs_ros.config import EstimatorConfig
    from switchobs_ros.pipeline import EstimatorPipeline

    conf = EstimatorConfig.from_files([REPO / "config" / name], {"gain_table": paper_tables[table]})
    pl = EstimatorPipeline.from_params(conf)
    assert pl.check and pl.screening.testing
    declared = name != "robot_template.yaml"
    assert (pl.observer.noise_max == (0.0, 0.0)) == declared and pl.screening.watch_only != declared
