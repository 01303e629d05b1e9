"""``python -m <module> <args>`` without a fresh interpreter's imports: a helper process (one per test
process, started at the first call) imports the tools' modules once, then forks a child per run.

The child is a process of its own, as a fresh ``python -m`` is: it gets the caller's working folder,
environment and resource limits, stdin from /dev/null, stdout and stderr to files the caller reads (the
Python and the C side), and runs the module as ``__main__`` (``runpy``, ``sys.argv[0]`` the module's
file, as ``-m`` sets it). It exits as the interpreter would: ``SystemExit``'s code, 1 and the traceback
for an uncaught exception (through ``sys.excepthook``), then the non-daemon threads joined, the ``atexit``
functions run and C's stdio flushed. A run past its timeout is killed and raises
``subprocess.TimeoutExpired``. What only a fresh interpreter shows (its own imports and exit) is checked
with one fresh run per tool (test_refusals_tools.py) and per node (test_startup_failures.py).
``SWITCHOBS_TEST_FRESH_TOOLS=1`` runs every tool in a fresh interpreter instead."""

from __future__ import annotations

import atexit
import json
import os
import subprocess
import sys
import tempfile
from collections.abc import Callable
from pathlib import Path

#: The modules the helper imports before it forks (what the refusal tests run).
PRELOAD = ("switchobs_core.cli", "switchobs_ros.entry", "switchobs_ros.estimator", "switchobs_ros.bag.cli")

_SERVER = r'''
import ctypes, importlib, json, os, resource, runpy, signal, sys, time
for m in sys.argv[1:]:
    importlib.import_module(m)
libc = ctypes.CDLL(None)
_in, _out = sys.stdin.buffer, os.fdopen(os.dup(1), "w")
for line in _in:
    req = json.loads(line)
    pid = os.fork()
    if pid == 0:
        code = 1
        try:
            signal.signal(signal.SIGINT, signal.default_int_handler)
            for lim, v in req["limits"]:
                resource.setrlimit(lim, tuple(v))
            os.chdir(req["cwd"])
            os.environ.clear()
            os.environ.update(req["env"])
            null = os.open(os.devnull, os.O_RDONLY)
            os.dup2(null, 0)
            for fd, path in ((1, req["out"]), (2, req["err"])):
                f = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
                os.dup2(f, fd)
                os.close(f)
            sys.stdin = open(0, closefd=False)
            sys.stdout = open(1, "w", closefd=False)
            sys.stderr = open(2, "w", closefd=False, errors="backslashreplace")
            sys.argv = [None, *req["args"]]
            try:
                runpy.run_module(req["module"], run_name="__main__", alter_sys=True)
                code = 0
            except SystemExit as e:
                if e.code is None:
                    code = 0
                elif isinstance(e.code, int):
                    code = e.code
                else:
                    print(e.code, file=sys.stderr)
                    code = 1
            except KeyboardInterrupt:
                code = -signal.SIGINT
            except BaseException:
                sys.excepthook(*sys.exc_info())
                code = 1
            import threading, atexit
            threading._shutdown()
            atexit._run_exitfuncs()
            for s in (sys.stdout, sys.stderr):
                try:
                    s.flush()
                except Exception:
                    pass
        finally:
            libc.fflush(None)
            if code == -signal.SIGINT:
                signal.signal(signal.SIGINT, signal.SIG_DFL)
                os.kill(os.getpid(), signal.SIGINT)
            os._exit(code & 0xFF)
    deadline = time.monotonic() + req["timeout"]
    timed_out = False
    while True:
        done, status = os.waitpid(pid, os.WNOHANG)
        if done:
            break
        if time.monotonic() > deadline:
            timed_out = True
            os.kill(pid, signal.SIGKILL)
            _, status = os.waitpid(pid, 0)
            break
        time.sleep(0.005)
    _out.write(json.dumps({"code": os.waitstatus_to_exitcode(status), "timeout": timed_out}) + "\n")
    _out.flush()
'''

_server: subprocess.Popen | None = None


def _start() -> subprocess.Popen:
    global _server
    if _server is None or _server.poll() is not None:
        _server = subprocess.Popen([sys.executable, "-c", _SERVER, *PRELOAD], stdin=subprocess.PIPE,
                                   stdout=subprocess.PIPE, text=True, bufsize=1)
        atexit.register(_stop)
    return _server


def _stop() -> None:
    global _server
    if _server is not None and _server.poll() is None:
        _server.stdin.close()
        try:
            _server.wait(10)
        except subprocess.TimeoutExpired:
            _server.kill()
            _server.wait()
    _server = None


def run_module(module: str, args: list[str], timeout: float, limits: list[tuple[int, tuple[int, int]]],
               fresh_preexec: Callable[[], None] | None = None) -> subprocess.CompletedProcess:
    """``python -m module args`` (captured, text) in a child of the helper, with ``limits``
    (``resource.setrlimit`` pairs) applied in the child; ``SWITCHOBS_TEST_FRESH_TOOLS=1``: a fresh
    interpreter (``fresh_preexec`` applies the limits there)."""
    cmd = [sys.executable, "-m", module, *args]
    if os.environ.get("SWITCHOBS_TEST_FRESH_TOOLS") == "1":
        return subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, preexec_fn=fresh_preexec)
    server = _start()
    with tempfile.TemporaryDirectory(prefix="switchobs_fork_") as d:
        out, err = Path(d) / "out", Path(d) / "err"
        req = {"module": module, "args": args, "cwd": os.getcwd(), "env": dict(os.environ), "out": str(out),
               "err": str(err), "timeout": timeout, "limits": [(k, list(v)) for k, v in limits]}
        server.stdin.write(json.dumps(req) + "\n")
        server.stdin.flush()
        line = server.stdout.readline()
        if not line:
            raise RuntimeError(f"the fork server exited with {server.wait()}")
        rep = json.loads(line)
        stdout = out.read_text(errors="replace") if out.exists() else ""
        stderr = err.read_text(errors="replace") if err.exists() else ""
    if rep["timeout"]:
        raise subprocess.TimeoutExpired(cmd, timeout, stdout, stderr)
    return subprocess.CompletedProcess(cmd, rep["code"], stdout, stderr)
