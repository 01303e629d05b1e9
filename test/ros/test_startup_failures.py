"""A bad configuration stops start-up: exit code != 0 and one line saying why (no traceback).

The refusals run the node's ``main`` in the test's process (refusals.node_main: its exit code and
its output, C side included); a fresh ``python -m switchobs_ros.<node>`` per node checks that
the process exits with that code and prints the same line (``fresh=True``)."""

from __future__ import annotations

import subprocess
import sys

import pytest
from refusals import node_main

from tools.launch import ros_args


def _run(node: str, args: list[str], timeout: float = 60.0, fresh: bool = False) -> subprocess.CompletedProcess:
    if not fresh:
        return node_main(node, args)
    return subprocess.run([sys.executable, "-m", f"switchobs_ros.{node}", *args], capture_output=True,
                          text=True, timeout=timeout)


def _assert_one_line_failure(res: subprocess.CompletedProcess, node: str, *needles: str) -> str:
    assert res.returncode != 0, res.stdout + res.stderr
    assert "Traceback" not in res.stderr and "Traceback" not in res.stdout, res.stderr
    ours = [ln for ln in res.stderr.splitlines() if ln.startswith(f"{node}: error:")]
    assert len(ours) == 1, res.stderr
    for n in needles:
        assert n in ours[0], ours[0]
    return ours[0]


@pytest.mark.parametrize("fresh", [False, True], ids=["in_process", "fresh_process"])
def test_missing_table_file(tmp_path, fresh):
    res = _run("estimator", ros_args(params={"gain_table": str(tmp_path / "nope.json")}), fresh=fresh)
    _assert_one_line_failure(res, "estimator", "gain_table", "nope.json", "does not exist")
    assert res.returncode == 2


def test_table_for_another_system(paper_tables, tmp_path):
    other = tmp_path / "other.yaml"
    other.write_text("scenario: camera_agents\nagents: 2\nD_agents: [[0, 0.3], [0, 0.1]]\n")
    res = _run("estimator", ros_args(params={"system": str(other), "gain_table": paper_tables["periodic"]}))
    _assert_one_line_failure(res, "estimator", "another system")


def test_unknown_scenario():
    res = _run("estimator", ros_args(params={"system": "no_such_scenario"}))
    _assert_one_line_failure(res, "estimator", "unknown scenario 'no_such_scenario'")


def test_malformed_params_file(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("estimator:\n  ros__parameters:\n    system: [paper\n    delta: 0.99\n")
    res = _run("estimator", ["--ros-args", "--params-file", str(bad)])
    _assert_one_line_failure(res, "estimator", "params")


@pytest.mark.parametrize("params,needle", [
    ({"schedule.tau": "two"}, "schedule.tau"),                      # a string where a double array goes
    ({"schedule.mode": "weekly"}, "schedule.mode"),
    ({"schedule.tua": [2.0]},
     "unknown parameter schedule.tua for node 'estimator' ('schedule.tua': did you mean 'schedule.tau'?)"),
    ({"initial_estimate": [1.0, 2.0]}, "initial_estimate"),
    ({"schedule.tau": [2.0, 3.0]}, "same, non-zero length"),         # tau and s disagree
    ({"schedule.tau": [2.0, 3.0], "schedule.s": [0.6, 0.5]}, "periodic' takes one cycle"),
])
def test_bad_parameters(params, needle, paper_tables):
    params = dict(params, gain_table=paper_tables["periodic"])
    res = _run("estimator", ros_args(params=params))
    _assert_one_line_failure(res, "estimator", needle)


@pytest.mark.parametrize("fresh", [False, True], ids=["in_process", "fresh_process"])
def test_camera_sim_bad_schedule(fresh):
    res = _run("camera_sim", ros_args(params={"schedule.s": [1.5]}), fresh=fresh)
    _assert_one_line_failure(res, "camera_sim", "schedule")
    assert res.returncode == 2
