"""Helpers of the refusal tests: run a tool as a user would, inside
the acceptance limits (30 s, 4 GB of address space), and check the one-line failure."""

from __future__ import annotations

import resource
import subprocess
import sys

#: The acceptance limits: wall time and address space of every tool run.
TIMEOUT_S = 30
ADDRESS_SPACE = 4 * 10**9


def _limits() -> None:
    resource.setrlimit(resource.RLIMIT_AS, (ADDRESS_SPACE, ADDRESS_SPACE))


def run(module: str, *args: str) -> subprocess.CompletedProcess:
    """``python -m <module> <args>`` within the acceptance limits."""
    return subprocess.run([sys.executable, "-m", module, *map(str, args)], capture_output=True, text=True,
                          timeout=TIMEOUT_S, preexec_fn=_limits)


def switchobs(*args: str) -> subprocess.CompletedProcess:
    return run("switchobs_core.cli", *args)


def switchobs_bag(*args: str) -> subprocess.CompletedProcess:
    return run("switchobs_ros.bag", *args)


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
