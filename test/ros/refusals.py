"""Helpers of the refusal tests: run a tool as a user would, inside
the acceptance limits (30 s, 4 GB of address space), in a process of its own (forked from a helper
with the tools imported: forkserver.py), and check the one-line failure; run a
node's ``main`` in the test's own process (a start-up refusal without a fresh interpreter)."""

from __future__ import annotations

import contextlib
import importlib
import io
import os
import resource
import subprocess
import sys
import tempfile

import forkserver

#: The acceptance limits: wall time and address space of every tool run.
TIMEOUT_S = 30
ADDRESS_SPACE = 4 * 10**9


def _limits() -> None:
    resource.setrlimit(resource.RLIMIT_AS, (ADDRESS_SPACE, ADDRESS_SPACE))


def run(module: str, *args: str, fresh: bool = False) -> subprocess.CompletedProcess:
    """``python -m <module> <args>`` within the acceptance limits: a process of its own forked from a
    helper that has the tools imported (forkserver.py), or with ``fresh`` a fresh interpreter (the
    process's own imports and exit path)."""
    if fresh:
        return subprocess.run([sys.executable, "-m", module, *map(str, args)], capture_output=True, text=True,
                              timeout=TIMEOUT_S, preexec_fn=_limits)
    return forkserver.run_module(module, list(map(str, args)), TIMEOUT_S,
                                 [(resource.RLIMIT_AS, (ADDRESS_SPACE, ADDRESS_SPACE))], fresh_preexec=_limits)


def switchobs(*args: str, fresh: bool = False) -> subprocess.CompletedProcess:
    return run("switchobs_core.cli", *args, fresh=fresh)


def switchobs_bag(*args: str, fresh: bool = False) -> subprocess.CompletedProcess:
    return run("switchobs_ros.bag", *args, fresh=fresh)


def assert_refused(res: subprocess.CompletedProcess, *needles: str, code: int | None = None) -> str:
    """Non-zero exit (``code`` if given), no traceback, at most 3 lines on stderr, one of them
    ``... error: ...`` holding every needle; returns that line."""
    assert res.returncode != 0 if code is None else res.returncode == code, (res.returncode, res.stderr)
    assert "Traceback" not in res.stderr + res.stdout, res.stderr
    lines = res.stderr.strip().splitlines()
    assert 1 <= len(lines) <= 3, res.stderr
    ours = [ln for ln in lines if "error:" in ln]
    assert len(ours) == 1, res.stderr
    for n in needles:
        assert n in ours[0], ours[0]
    return ours[0]


def node_main(node: str, args: list[str], timeout: float = TIMEOUT_S) -> subprocess.CompletedProcess:
    """``switchobs_ros.<node>.main`` called in this process with ``[node, *args]`` for its
    ``sys.argv``: what ``python -m switchobs_ros.<node> <args>`` exits with (its ``__main__`` is
    ``sys.exit(main())``) and writes, both the Python and the C side (rcl, rcutils logging) of
    stdout and stderr. An exception out of ``main`` (a traceback in a fresh process) is raised
    here. A node that starts instead of refusing is shut down after ``timeout`` seconds (exit code
    0, which no refusal check accepts). The fresh process's own exit path is checked once per node
    (test_startup_failures.py)."""
    import threading

    import rclpy

    mod = importlib.import_module(f"switchobs_ros.{node}")
    watchdog = threading.Timer(timeout, rclpy.try_shutdown)
    watchdog.daemon = True
    watchdog.start()
    hook = sys.unraisablehook                           # run_node wraps it: put it back after
    sys.stdout.flush()
    sys.stderr.flush()
    saved = os.dup(1), os.dup(2)
    py_out, py_err = io.StringIO(), io.StringIO()
    with tempfile.TemporaryFile("w+") as c_out, tempfile.TemporaryFile("w+") as c_err:
        try:
            os.dup2(c_out.fileno(), 1)
            os.dup2(c_err.fileno(), 2)
            with contextlib.redirect_stdout(py_out), contextlib.redirect_stderr(py_err):
                code = mod.main([node, *map(str, args)])
        finally:
            os.dup2(saved[0], 1)
            os.dup2(saved[1], 2)
            os.close(saved[0])
            os.close(saved[1])
            sys.unraisablehook = hook
            watchdog.cancel()
        c_out.seek(0)
        c_err.seek(0)
        out, err = py_out.getvalue() + c_out.read(), c_err.read() + py_err.getvalue()
    return subprocess.CompletedProcess([node, *args], code, out, err)
