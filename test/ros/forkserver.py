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
import signal
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable
from pathlib import Path

#: The modules the helper imports before it forks (what the refusal tests run).
PRELOAD = ("switchobs_core.cli", "switchobs_ros.entry", "switchobs_ros.estimator", "switchobs_ros.camera_sim",
           "switchobs_ros.bag.cli")

_SERVER = r'''
import ctypes, importlib, io, json, os, resource, runpy, signal, sys
for m in sys.argv[1:]:
    importlib.import_module(m)
libc = ctypes.CDLL(None)
_in, _out = sys.stdin.buffer, os.fdopen(os.dup(1), "w")


def child(req):
    code = 1
    try:
        os.close(_out.fileno())
        signal.signal(signal.SIGINT, signal.default_int_handler)
        for lim, v in req["limits"]:
            resource.setrlimit(lim, tuple(v))
        os.chdir(req["cwd"])
        os.environ.clear()
        os.environ.update(req["env"])
        null = os.open(os.devnull, os.O_RDONLY)
        os.dup2(null, 0)
        for fd, path in ((1, req["out"]), (2, req["err"])):
            if path is None:
                os.dup2(1, 2)
                continue
            f = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
            os.dup2(f, fd)
            os.close(f)
        unbuffered = bool(os.environ.get("PYTHONUNBUFFERED"))
        sys.stdin = open(0, closefd=False)
        sys.stdout = io.TextIOWrapper(open(1, "wb", buffering=0 if unbuffered else -1, closefd=False),
                                      write_through=unbuffered)
        sys.stderr = io.TextIOWrapper(open(2, "wb", buffering=0, closefd=False), errors="backslashreplace",
                                      write_through=True, line_buffering=True)
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
        import atexit
        import threading
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


for line in _in:
    req = json.loads(line)
    if req["op"] == "spawn":
        pid = os.fork()
        if pid == 0:
            child(req)
        rep = {"pid": pid}
    else:
        done, status = os.waitpid(req["pid"], 0 if req.get("block") else os.WNOHANG)
        rep = {"code": os.waitstatus_to_exitcode(status) if done else None}
    _out.write(json.dumps(rep) + "\n")
    _out.flush()
'''

_server: subprocess.Popen | None = None
_lock = threading.Lock()


def _request(req: dict) -> dict:
    global _server
    with _lock:
        if _server is None or _server.poll() is not None:
            _server = subprocess.Popen([sys.executable, "-c", _SERVER, *PRELOAD], stdin=subprocess.PIPE,
                                       stdout=subprocess.PIPE, text=True, bufsize=1)
            atexit.register(stop)
        _server.stdin.write(json.dumps(req) + "\n")
        _server.stdin.flush()
        line = _server.stdout.readline()
        if not line:
            raise RuntimeError(f"the fork server exited with {_server.wait()}")
        return json.loads(line)


def stop() -> None:
    """End the helper (its children are ended by their owners) and wait for it."""
    global _server
    if _server is not None and _server.poll() is None:
        _server.stdin.close()
        try:
            _server.wait(10)
        except subprocess.TimeoutExpired:
            _server.kill()
            _server.wait()
    _server = None


class ForkedProcess:
    """The part of ``subprocess.Popen`` the tests use (``pid``, ``returncode``, ``poll``, ``wait``,
    ``send_signal``, ``terminate``, ``kill``) for ``python -m module args`` forked by the helper."""

    def __init__(self, cmd: list[str], module: str, args: list[str], *, out: str | None, err: str | None,
                 env: dict | None = None, limits: list[tuple[int, tuple[int, int]]] = ()):
        self.args = cmd
        self.returncode: int | None = None
        self.pid = _request({"op": "spawn", "module": module, "args": args, "cwd": os.getcwd(),
                             "env": dict(os.environ if env is None else env), "out": out, "err": err,
                             "limits": [(k, list(v)) for k, v in limits]})["pid"]

    def poll(self) -> int | None:
        if self.returncode is None:
            self.returncode = _request({"op": "poll", "pid": self.pid})["code"]
        return self.returncode

    def wait(self, timeout: float | None = None) -> int:
        end = None if timeout is None else time.monotonic() + timeout
        while self.poll() is None:
            if end is not None and time.monotonic() > end:
                raise subprocess.TimeoutExpired(self.args, timeout)
            time.sleep(0.005)
        return self.returncode

    def send_signal(self, sig: int) -> None:
        if self.poll() is None:
            os.kill(self.pid, sig)

    def terminate(self) -> None:
        self.send_signal(signal.SIGTERM)

    def kill(self) -> None:
        self.send_signal(signal.SIGKILL)


def module_of(cmd: list[str]) -> tuple[str, list[str]] | None:
    """``(module, args)`` of ``[sys.executable, "-m", module, *args]``, else None (not forkable)."""
    if len(cmd) >= 3 and cmd[0] == sys.executable and cmd[1] == "-m" \
            and os.environ.get("SWITCHOBS_TEST_FRESH_TOOLS") != "1":
        return cmd[2], list(cmd[3:])
    return None


def popen(cmd: list[str], stdout, stderr, env: dict) -> subprocess.Popen | ForkedProcess:
    """``tools.launch.NodeProcess``'s start (``NodeProcess.spawner``): a forked child for ``python -m``
    with ``stdout`` a log file (or DEVNULL) and stderr to it, else ``subprocess.Popen``. An environment
    other than this process's (a preloaded library, say) gets a fresh interpreter."""
    mod = module_of(cmd)
    same_env = {k: v for k, v in env.items() if k not in _NODE_ENV} == \
        {k: v for k, v in os.environ.items() if k not in _NODE_ENV}
    if mod is None or not same_env or stderr is not subprocess.STDOUT:
        return subprocess.Popen(cmd, stdout=stdout, stderr=stderr, env=env)
    out = os.devnull if stdout is subprocess.DEVNULL else stdout.name
    if out != os.devnull:
        stdout.flush()
    return ForkedProcess(cmd, *mod, out=out, err=None, env=env)


#: What NodeProcess adds to the caller's environment (a fork with them still has the same libraries).
_NODE_ENV = ("ROS_AUTOMATIC_DISCOVERY_RANGE", "PYTHONUNBUFFERED", "RCUTILS_COLORIZED_OUTPUT")


def run_module(module: str, args: list[str], timeout: float, limits: list[tuple[int, tuple[int, int]]],
               fresh_preexec: Callable[[], None] | None = None) -> subprocess.CompletedProcess:
    """``python -m module args`` (captured, text) in a child of the helper, with ``limits``
    (``resource.setrlimit`` pairs) applied in the child; ``SWITCHOBS_TEST_FRESH_TOOLS=1``: a fresh
    interpreter (``fresh_preexec`` applies the limits there)."""
    cmd = [sys.executable, "-m", module, *args]
    if module_of(cmd) is None:
        return subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, preexec_fn=fresh_preexec)
    with tempfile.TemporaryDirectory(prefix="switchobs_fork_") as d:
        out, err = Path(d) / "out", Path(d) / "err"
        proc = ForkedProcess(cmd, module, args, out=str(out), err=str(err), limits=limits)
        try:
            proc.wait(timeout)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
            raise subprocess.TimeoutExpired(cmd, timeout, out.read_text(errors="replace"),
                                            err.read_text(errors="replace")) from None
        stdout = out.read_text(errors="replace") if out.exists() else ""
        stderr = err.read_text(errors="replace") if err.exists() else ""
    return subprocess.CompletedProcess(cmd, proc.returncode, stdout, stderr)
