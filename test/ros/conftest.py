"""ROS tests: a ROS_DOMAIN_ID of this session's own, localhost-only discovery.

Set at import (before any rclpy use or child process): ``ROS_AUTOMATIC_DISCOVERY_RANGE =
LOCALHOST`` and a ``ROS_DOMAIN_ID`` claimed with a lock file (tools.domain), held
for the whole session, so concurrent sessions on the machine never share a domain.
"""

from __future__ import annotations

import os

import pytest

try:
    import rclpy  # noqa: F401
    HAVE_ROS = True
except ImportError:  # pragma: no cover - the ROS wheels are in requirements.txt
    HAVE_ROS = False

if HAVE_ROS:
    from tools.domain import claim_domain

    _LEASE = claim_domain()
    os.environ["ROS_DOMAIN_ID"] = str(_LEASE.domain_id)
    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    os.environ.pop("ROS_LOCALHOST_ONLY", None)
    os.environ["SWITCHOBS_CLAIM_DOMAIN"] = "0"   # the demo runner uses ours
    os.environ.setdefault("RCUTILS_COLORIZED_OUTPUT", "0")

    import forkserver

    from tools.launch import NodeProcess

    # the nodes start forked from a helper with them imported, not as fresh interpreters (forkserver.py)
    NodeProcess.spawner = staticmethod(forkserver.popen)
else:
    collect_ignore_glob = ["test_*.py"]


def pytest_collection_modifyitems(config, items):
    for item in items:
        if "test/ros" in str(item.fspath).replace(os.sep, "/"):
            item.add_marker(pytest.mark.ros)


@pytest.fixture(scope="session", autouse=True)
def _fork_server():
    """The fork server (forkserver.py) stops at the end of the session: this process waits for it (and so
    its time counts in this one's children, and no child of it outlives the run)."""
    yield
    import forkserver

    forkserver.stop()


@pytest.fixture(scope="session")
def ros_domain() -> int:
    return int(os.environ["ROS_DOMAIN_ID"])


@pytest.fixture(scope="session")
def paper_tables(run_cache):
    """Gain tables for the paper's periodic and sequence schedules, designed once per test run
    (the pytest-xdist workers share them: test/conftest.py, ``run_cache``)."""
    from switchobs_core.design.lmi import design_table
    from switchobs_core.model.scenarios import load_system
    from switchobs_core.model.schedule import Cycle

    def make(d):
        sys_ = load_system("paper")
        design_table(sys_, [Cycle.from_ts(2.0, 0.6)], delta=0.99).save(d / "periodic.json")
        design_table(sys_, [Cycle.from_ts(4.0, 0.5), Cycle.from_ts(3.0, 0.6), Cycle.from_ts(2.0, 0.4)],
                     delta=0.99).save(d / "sequence.json")
    d = run_cache("paper_tables", make)
    return {"periodic": str(d / "periodic.json"), "sequence": str(d / "sequence.json")}


@pytest.fixture(scope="session")
def bag(run_cache):
    """A small input bag (2 s at 20 Hz) as the tool writes it (``switchobs_bag generate``), made once
    per test run and only read (test_refusals_tools.py, test_refusals_inputs.py). A module's own
    ``bag`` fixture replaces it there."""
    from refusals import switchobs_bag

    def make(d):
        res = switchobs_bag("generate", d / "in", "--duration", "2", "--rate", "20")
        assert res.returncode == 0, res.stderr
    return run_cache("small_bag", make) / "in"


@pytest.fixture(scope="session")
def colcon_workspace(run_cache):
    """The documented colcon build (docs/how-to/ros2.md) of a copy of the repository, made once per
    test run (test_colcon_package.build_documented_workspace): (the workspace, the build's
    ``{"returncode", "output"}``). test_colcon_package.py and test_typed_msgs.py check it."""
    import json

    from test_colcon_package import build_documented_workspace

    ws = run_cache("colcon_ws", build_documented_workspace)
    return ws, json.loads((ws / "build.json").read_text())


@pytest.fixture
def ros_node():
    """An rclpy context and a plain node for the test's own publishers/subscribers."""
    import rclpy
    from rclpy.node import Node

    rclpy.init()
    node = Node("switchobs_test")
    yield node
    node.destroy_node()
    rclpy.try_shutdown()
