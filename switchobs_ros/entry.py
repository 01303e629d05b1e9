"""The nodes' console scripts (``ros2 run switchobs_ros estimator`` and the others).

A node's module imports rclpy, numpy, scipy and the gain-design stack before its ``main`` runs:
about a second in which Python's default SIGINT handler would turn a Ctrl-C into the traceback of
whatever import it interrupted. These entry points import the node under a handler that makes
that Ctrl-C a quiet stop with exit code 0 (the runner's contract for a Ctrl-C, see
:mod:`switchobs_ros.runner`): nothing has started yet, so there is nothing to clean up. Once the
module is imported the usual handling takes over (:func:`~switchobs_ros.runner.run_node`).

This module imports nothing heavy itself, so that the handler is in place at once.
``python -m switchobs_ros.<node>`` still runs the module directly.
"""

from __future__ import annotations

import importlib
import os
import signal


def _stop_quietly(signum, frame) -> None:
    os._exit(0)     # no rclpy context, no open outputs yet: a plain exit, no traceback


def _run(module: str) -> int:
    """Import ``switchobs_ros.<module>`` with a Ctrl-C meaning "stop", then run its ``main``."""
    previous = signal.signal(signal.SIGINT, _stop_quietly)
    try:
        node = importlib.import_module(f"switchobs_ros.{module}")
    finally:
        signal.signal(signal.SIGINT, previous)
    return node.main()


def estimator() -> int:
    """``estimator``: :mod:`switchobs_ros.estimator`."""
    return _run("estimator")


def managed_estimator() -> int:
    """``managed_estimator``: :mod:`switchobs_ros.managed_estimator`."""
    return _run("managed_estimator")


def camera_sim() -> int:
    """``camera_sim``: :mod:`switchobs_ros.camera_sim`."""
    return _run("camera_sim")
