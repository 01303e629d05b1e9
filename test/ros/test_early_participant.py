"""The estimator's console script creates its DDS participant before importing the node
(:mod:`switchobs_ros.early`): ``run_node`` builds the node in that context, with rclpy's signal
handlers, and releases the bare node once the estimator's exists; start-up refusals stay one line
with exit code 2, a bad ``--ros-args`` refused as without the early context."""

from __future__ import annotations

import subprocess
import sys

import pytest
from refusals import TIMEOUT_S, assert_refused

from switchobs_core.table.gains import GainTable
from tools.launch import ros_args

#: How ``ros2 run switchobs_ros estimator`` starts (the console script's function).
SCRIPT = "import sys; from switchobs_ros.entry import estimator; sys.exit(estimator())"

#: The console script's start with a node that records what it finds once built, then stops.
PROBE = """
import gc
import sys
print("gc thresholds at the start:", gc.get_threshold(), flush=True)
import rclpy
from rclpy.signals import SignalHandlerOptions, get_current_signal_handlers_options
from switchobs_ros import early, entry, runner
from switchobs_ros.estimator import EstimatorNode

class Probe(EstimatorNode):
    def __init__(self):
        print("boot before the node:", early.started(), rclpy.ok(), "gc", gc.isenabled(), gc.get_freeze_count() > 1000,
              gc.get_threshold()[0] == early.BUILD_GEN0, flush=True)
        super().__init__()
        self.create_timer(0.0, self.report)

    def report(self):
        names = [n for n, _ in self.get_node_names_and_namespaces()]
        print("boot after the node:", early.started(), "estimator" in names,
              get_current_signal_handlers_options() == SignalHandlerOptions.ALL, "gc", gc.get_threshold(), flush=True)
        rclpy.try_shutdown()

import switchobs_ros.estimator as node_module
node_module.main = lambda args=None: runner.run_node(Probe, "estimator", args)
sys.exit(entry.estimator())
"""


def _run(code: str, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", code, *args], capture_output=True, text=True, timeout=TIMEOUT_S)


def test_node_built_in_the_early_context(paper_tables):
    """Through the console script: the context and its bare node exist before the node is built, what the
    imports made is frozen (collection was off during them) and garbage collection is on again, its youngest
    generation's threshold raised while the node is built; the node is built in that context and ready with
    the table given; once it exists the bare node is gone, the thresholds are Python's defaults again and
    rclpy's signal handlers are installed; the stop is exit 0."""
    res = _run(PROBE, *ros_args(params={"gain_table": paper_tables["periodic"]}))
    assert res.returncode == 0, res.stderr
    out = res.stdout + res.stderr
    assert "boot before the node: True True gc True True True" in out, out
    start = out.split("gc thresholds at the start: ", 1)[1].split("\n", 1)[0]
    assert f"boot after the node: False True True gc {start}" in out, out
    assert "estimator ready: system 'paper'" in out and paper_tables["periodic"] in out, out
    assert "Traceback" not in out, out


def test_console_script_refuses_a_bad_table_in_one_line(paper_tables, tmp_path):
    """A truncated .npz through the console script: one line, exit code 2."""
    data = GainTable.load(paper_tables["periodic"]).save(tmp_path / "good.npz").read_bytes()
    bad = tmp_path / "truncated.npz"
    bad.write_bytes(data[: len(data) // 2])
    res = _run(SCRIPT, *ros_args(params={"gain_table": str(bad)}))
    assert_refused(res, "estimator: error:", "gain_table", "truncated.npz", "truncated", code=2)


def test_console_script_refuses_bad_ros_args_as_run_node_does():
    """``rclpy.init`` fails in the early start: ``run_node`` refuses it in one line (its own message,
    exit code 2), and rcl's own complaint is printed once, not once per attempt."""
    res = _run(SCRIPT, "--ros-args", "-p", "gain_table:=[1")
    line = assert_refused(res, "estimator: error: cannot start ROS 2:", "gain_table:=[1", code=2)
    assert line.startswith("estimator: error: cannot start ROS 2: failed to initialize rcl")
    assert res.stderr.count("Failed to parse global arguments") == 1, res.stderr


@pytest.mark.parametrize("module", ["estimator", "managed_estimator"])
def test_python_m_starts_as_the_console_script(module):
    """``python -m switchobs_ros.estimator`` (and ``managed_estimator``) runs the console script's start
    (the heap kept; the estimator's participant first): the module run as ``__main__`` hands over to
    its ``entry`` function before it imports rclpy, numpy or the node, and the process exits with what
    that returns."""
    code = ("import runpy, sys\n"
            "from switchobs_ros import entry\n"
            f"entry.{module} = lambda: print('console start', 'rclpy' in sys.modules, 'numpy' in sys.modules) or 7\n"
            f"runpy.run_module('switchobs_ros.{module}', run_name='__main__', alter_sys=True)\n")
    res = _run(code)
    assert res.returncode == 7, res.stderr
    assert res.stdout.strip() == "console start False False", res.stdout + res.stderr
