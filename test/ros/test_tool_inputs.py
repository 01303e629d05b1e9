"""Bad arguments to the ROS-side tools and nodes (every bad input gets one clear line):
camera_sim's numbers, the demo's flags, the estimator's parameters (an integer for a double is
accepted; an empty list or an empty world_frame is refused), a deep gain table, and negative-
looking values after an option."""

from __future__ import annotations

import subprocess
import sys

import pytest
from test_startup_failures import _assert_one_line_failure, _run

from switchobs_core.cli._common import join_negative_values
from tools.launch import ros_args


@pytest.mark.parametrize("params, needles", [
    ({"duration": -5.0}, ("duration", ">= 0", "0 runs until stopped")),
    ({"noise_std": -1.0}, ("noise_std", ">= 0")),
    ({"rate": float("inf")}, ("rate", "finite")),
    ({"world_frame": ""}, ("world_frame", "empty")),
])
def test_camera_sim_refuses_bad_numbers(params, needles):
    """camera_sim took duration <= 0 as "run forever" and accepted a negative noise std."""
    res = _run("camera_sim", ros_args(params=params), timeout=60)
    _assert_one_line_failure(res, "camera_sim", *needles)


@pytest.mark.parametrize("argv, needle", [
    (["--duration", "-5"], "--duration: must be a finite number > 0; got -5"),
    (["--rate", "0"], "--rate: must be a finite number > 0"),
    (["--noise", "-1"], "--noise: must be a finite number >= 0"),
])
def test_demo_refuses_bad_flags_at_once(argv, needle):
    """`scripts/demo.sh --duration -5` never ended and burned CPU: now one line, exit 2, at once."""
    res = subprocess.run([sys.executable, "-m", "tools.demo", *argv], capture_output=True, text=True, timeout=30)
    assert res.returncode == 2
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and needle in lines[0] and "Traceback" not in res.stderr, res.stderr


def test_estimator_accepts_an_integer_for_a_double_and_refuses_empty_values(paper_tables, tmp_path):
    """-p e0:=5 is harmless (was refused); `tau: []` was silently replaced by the default; an empty
    world_frame was accepted."""
    empty = tmp_path / "empty.yaml"
    empty.write_text("estimator:\n  ros__parameters:\n    schedule:\n      tau: []\n")
    res = _run("estimator", ["--ros-args", "--params-file", str(empty)])
    _assert_one_line_failure(res, "estimator", "schedule.tau", "is empty", "[2.0]")
    res = _run("estimator", ros_args(params={"world_frame": ""}))
    _assert_one_line_failure(res, "estimator", "world_frame", "must not be empty")
    # e0:=5 (an integer) with a bad table: the run gets past the parameter and fails on the table
    res = _run("estimator", ["--ros-args", "-p", "e0:=5", "-p", f"gain_table:={tmp_path / 'nope.json'}"])
    _assert_one_line_failure(res, "estimator", "nope.json", "does not exist")


def test_estimator_deep_gain_table_is_one_line(tmp_path):
    """A gain table nested 100 000 deep: the estimator's one-line error (was a traceback, exit 1)."""
    deep = tmp_path / "deep.json"
    deep.write_text("[" * 100_000 + "]" * 100_000)
    res = _run("estimator", ros_args(params={"gain_table": str(deep)}))
    _assert_one_line_failure(res, "estimator", "deep.json", "nested deeper")


def test_negative_values_after_an_option():
    assert join_negative_values(["design", "paper", "--cycle", "-2,0.6", "-o", "x"]) == \
        ["design", "paper", "--cycle=-2,0.6", "-o", "x"]
    assert join_negative_values(["--cycle", "2,0.6", "--json"]) == ["--cycle", "2,0.6", "--json"]
    assert join_negative_values(["--eta", "-.5,1"]) == ["--eta=-.5,1"]


@pytest.mark.parametrize("when", ["ROS_DOMAIN_ID", "cycle"])
def test_demo_interrupted_exits_quietly(tmp_path, when):
    """Ctrl-C (SIGINT to the process group, as a terminal sends it) while the estimator starts
    (after the ROS_DOMAIN_ID line) or while the per-cycle rows print: one line, exit 130, the nodes
    stopped (no traceback, no 'context is not valid', no 'estimator exited')."""
    import os
    import signal
    import time

    p = subprocess.Popen([sys.executable, "-m", "tools.demo", "--duration", "120", "--out", str(tmp_path)],
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True)
    try:
        deadline = time.monotonic() + 120
        line = ""
        while when not in line and time.monotonic() < deadline:
            line = p.stdout.readline()
            if not line and p.poll() is not None:
                break
        assert when in line, p.stderr.read()
        os.killpg(p.pid, signal.SIGINT)
        rc = p.wait(timeout=60)
    finally:
        if p.poll() is None:
            os.killpg(p.pid, signal.SIGKILL)
            p.wait()
    err = p.stderr.read()
    assert rc == 130, err
    assert "demo: interrupted; the nodes are stopped" in err
    assert "Traceback" not in err and "context is not valid" not in err and "exited with" not in err, err


@pytest.mark.parametrize("node", ["estimator", "managed_estimator", "camera_sim"])
@pytest.mark.parametrize("delay", [0.15, 0.5, 1.0])
def test_node_interrupted_during_its_imports_stops_quietly(node, delay):
    """Ctrl-C while the node's console script still imports rclpy, numpy and the rest (about a
    second), or while the node is being built: exit 0 and no traceback (switchobs_ros.entry;
    before it, the interrupted import's traceback and exit 130; and the runner's unraisable hook:
    rclpy's KeyboardInterrupt inside a finalizer printed "Exception ignored ... Traceback", seen in
    CI at 0.5 s)."""
    import os
    import signal
    import time
    from pathlib import Path

    exe = Path(sys.executable).parent / node
    assert exe.exists(), f"{exe}: the package's console scripts are not installed (scripts/bootstrap.sh)"
    p = subprocess.Popen([str(exe)], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                         start_new_session=True)
    try:
        time.sleep(delay)
        os.killpg(p.pid, signal.SIGINT)
        out, err = p.communicate(timeout=60)
    finally:
        if p.poll() is None:
            os.killpg(p.pid, signal.SIGKILL)
            p.wait()
    assert p.returncode == 0, err
    assert "Traceback" not in out + err, err


def test_runner_drops_only_keyboard_interrupts_raised_in_finalizers():
    """The runner's ``sys.unraisablehook``: a KeyboardInterrupt in a ``__del__`` (rclpy's SIGINT
    handler firing there) is dropped; any other unraisable exception reaches the previous hook."""
    from types import SimpleNamespace

    from switchobs_ros.runner import _quiet_interrupt_in_finalizers

    seen = []
    hook = _quiet_interrupt_in_finalizers(seen.append)
    hook(SimpleNamespace(exc_type=KeyboardInterrupt, exc_value=KeyboardInterrupt(), object=None))
    assert seen == []
    other = SimpleNamespace(exc_type=ValueError, exc_value=ValueError("x"), object=None)
    hook(other)
    assert seen == [other]
