"""Start switchobs nodes as separate processes and collect what they publish.

There is no ``launch`` package in the PyPI ROS 2 wheels, so the demo, the tests and the
benchmark start the executables with :class:`NodeProcess` and listen with a
:class:`Collector` node. Every child gets ``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`` and the
caller's ``ROS_DOMAIN_ID`` (see :mod:`tools.domain`).
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from collections.abc import Sequence
from pathlib import Path

import numpy as np
from rclpy.node import Node
from std_msgs.msg import Float64MultiArray

import msg_bridge as mb
from switchobs_ros import qos

__all__ = ["NodeProcess", "Collector", "ros_args"]


def ros_args(params_files: Sequence[str | Path] = (), params: dict | None = None) -> list[str]:
    """``--ros-args --params-file F ... -p name:=value ...``."""
    out = ["--ros-args"]
    for f in params_files:
        out += ["--params-file", str(f)]
    for k, v in (params or {}).items():
        if isinstance(v, bool):
            v = "true" if v else "false"
        elif isinstance(v, (list, tuple)):
            v = "[" + ",".join(repr(float(x)) if isinstance(x, float) else str(x) for x in v) + "]"
        elif isinstance(v, str) and (v == "" or ":" in v or v.strip() != v):
            v = "'" + v.replace("'", "''") + "'"
        out += ["-p", f"{k}:={v}"]
    return out


class NodeProcess:
    """One node executable in its own process (``python -m switchobs_ros.<name>`` by default)."""

    #: What starts the process (``subprocess.Popen``'s signature and interface; the ROS tests fork
    #: it from a helper with the nodes imported: test/ros/forkserver.py).
    spawner = staticmethod(subprocess.Popen)

    def __init__(self, name: str, args: Sequence[str] = (), *, cmd: Sequence[str] | None = None,
                 log: str | Path | None = None, env: dict | None = None):
        self.name = name
        self.cmd = list(cmd) if cmd else [sys.executable, "-m", f"switchobs_ros.{name}"]
        self.cmd += list(args)
        env = dict(os.environ if env is None else env)
        env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
        if "ROS_DOMAIN_ID" not in env:
            raise RuntimeError("ROS_DOMAIN_ID must be set (claim one with tools.domain)")
        env.setdefault("PYTHONUNBUFFERED", "1")
        env.setdefault("RCUTILS_COLORIZED_OUTPUT", "0")
        self.log_path = Path(log) if log else None
        self._log = open(self.log_path, "w") if self.log_path else subprocess.DEVNULL
        self.proc = self.spawner(self.cmd, stdout=self._log, stderr=subprocess.STDOUT, env=env)
        self.pid = self.proc.pid

    def alive(self) -> bool:
        return self.proc.poll() is None

    def wait(self, timeout: float | None = None) -> int:
        return self.proc.wait(timeout)

    def stop(self, timeout: float = 5.0) -> int | None:
        """SIGINT (the node's clean shutdown), then SIGKILL after ``timeout``; our own PID only."""
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGINT)
            try:
                self.proc.wait(timeout)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        if self._log is not subprocess.DEVNULL:
            self._log.close()
        return self.proc.returncode

    def output(self) -> str:
        return self.log_path.read_text() if self.log_path and self.log_path.exists() else ""


class Collector(Node):
    """Keeps every labelled array it receives on the given topics, keyed by stamp."""

    def __init__(self, topics: Sequence[str], name: str = "switchobs_collector"):
        super().__init__(name)
        self.data: dict[str, dict[int, np.ndarray]] = {t: {} for t in topics}
        self.labels: dict[str, tuple[str, ...]] = {}
        self.arrival: dict[str, dict[int, float]] = {t: {} for t in topics}
        self.subs = [self.create_subscription(Float64MultiArray, t, self._cb(t), qos.TRUTH) for t in topics]

    def _cb(self, topic: str):
        def callback(msg: Float64MultiArray) -> None:
            arr = mb.unpack_labelled(msg)
            self.data[topic][arr.stamp_ns] = arr.values
            self.arrival[topic][arr.stamp_ns] = time.time()
            self.labels.setdefault(topic, arr.labels)
        return callback

    def matched(self, topics: Sequence[str] | None = None) -> bool:
        """Every subscription (or those on ``topics``) sees at least one publisher."""
        names = [s.topic_name for s in self.subs] if topics is None else topics
        return all(self.count_publishers(t) > 0 for t in names)
