"""What the live subcommands share: a stop flag for SIGINT/SIGTERM, the node, the log line."""

from __future__ import annotations

import signal
from collections.abc import Iterator
from contextlib import contextmanager

import rclpy
from rclpy.signals import SignalHandlerOptions

__all__ = ["PROG", "StopFlag", "log", "ros_node", "split_ros_args"]

PROG = "switchobs_bag"


def split_ros_args(argv: list[str]) -> tuple[list[str], list[str]]:
    """``argv`` before ``--ros-args``, and the ROS arguments (from ``--ros-args`` on)."""
    if "--ros-args" in argv:
        i = argv.index("--ros-args")
        return argv[:i], argv[i:]
    return argv, []


class StopFlag:
    """SIGINT/SIGTERM set a flag; the loops check it and close the bag cleanly."""

    def __init__(self) -> None:
        self.stop = False
        for s in (signal.SIGINT, signal.SIGTERM):
            signal.signal(s, self._handler)

    def _handler(self, *_) -> None:
        self.stop = True

    def __call__(self) -> bool:
        return self.stop


@contextmanager
def ros_node(name: str, ros_argv: list[str]) -> Iterator:
    """A node of its own context (rclpy's signal handlers off: :class:`StopFlag` has the signals)."""
    rclpy.init(args=[PROG, *ros_argv], signal_handler_options=SignalHandlerOptions.NO)
    node = rclpy.create_node(name)
    try:
        yield node
    finally:
        node.destroy_node()
        rclpy.try_shutdown()


def log(text: str) -> None:
    print(f"{PROG}: {text}", flush=True)
