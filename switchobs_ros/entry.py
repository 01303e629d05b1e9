"""The nodes' console scripts (``ros2 run switchobs_ros estimator`` and the others).

A node's module imports rclpy, numpy, scipy and the gain-design stack before its ``main`` runs:
about a second in which Python's default SIGINT handler would turn a Ctrl-C into the traceback of
whatever import it interrupted. These entry points import the node under a handler that makes
that Ctrl-C a quiet stop with exit code 0 (the runner's contract for a Ctrl-C, see
:mod:`switchobs_ros.runner`): nothing has started yet, so there is nothing to clean up. Once the
module is imported the usual handling takes over (:func:`~switchobs_ros.runner.run_node`).

This module imports nothing heavy itself, so that the handler is in place at once. The estimator's
DDS participant is created before its module is imported (:mod:`switchobs_ros.early`), so that DDS
discovery runs during the imports; scipy is imported without the numpy submodules its namespace copy
would import (:mod:`switchobs_core.lean_scipy`). The estimators' console scripts first set glibc's
malloc to keep the heap between samples (:mod:`switchobs_ros.heap`: a process-wide setting, made
once, before the imports allocate), and they and the bag tool's set one BLAS thread before numpy
loads its BLAS (:func:`switchobs_core.threads.single_thread_before_load`). A ``pip install``
without the interface package switchobs_msgs gets one line saying how to build it (exit code 2),
not an import traceback.
``python -m switchobs_ros.estimator`` starts through :func:`estimator` as well (the module hands over
before its imports); ``python -m`` of the other nodes runs the module directly.
"""

from __future__ import annotations

import gc
import importlib
import os
import signal
import sys


def _stop_quietly(signum, frame) -> None:
    os._exit(0)     # no rclpy context, no open outputs yet: a plain exit, no traceback


#: What a missing interface package (a ``pip install`` without the message build) is told.
NO_MSGS = ("the interface package switchobs_msgs (the typed outputs' messages) is not installed: build it into "
           "this environment with `bash scripts/build_msgs.sh`, or build it with colcon beside switchobs_ros "
           "(docs/how-to/ros2.md)")


def _run(module: str, prog: str, participant_first: bool = False, keep_heap: bool = False,
         one_blas_thread: bool = False, frozen_imports: bool = False) -> int:
    """Import ``switchobs_ros.<module>`` with a Ctrl-C meaning "stop", then run its ``main``; a missing
    switchobs_msgs is one line on stderr and exit code 2. ``participant_first``: the node's DDS
    participant is created before the import (:mod:`switchobs_ros.early`); ``keep_heap``: glibc's
    malloc keeps the heap between samples, set before anything but the BLAS threads (:mod:`switchobs_ros.heap`);
    ``one_blas_thread``: one BLAS thread, set before numpy loads one
    (:func:`switchobs_core.threads.single_thread_before_load`); ``frozen_imports``: garbage collection
    off while the module is imported (numpy's and scipy's namespaces, rclpy, the tool's modules and
    their dataclasses: about a hundred collections over objects that live as long as the process,
    50-100 ms of a replay's CPU, bench/RESULTS.md section replay11), then what the imports made frozen
    (:func:`gc.freeze`) and collection on again, as :mod:`switchobs_ros.early` does for the estimator.
    Here, in the console script, not in the module: a library that imports the module keeps its own
    collection."""
    if one_blas_thread:
        from switchobs_core.threads import single_thread_before_load
        single_thread_before_load()
    if keep_heap:
        from .heap import keep_heap as keep
        keep()
    previous = signal.signal(signal.SIGINT, _stop_quietly)
    paused = frozen_imports and gc.isenabled()
    try:
        if paused:
            gc.disable()
        if participant_first:
            from . import early
            early.start(prog)
        from switchobs_core.lean_scipy import import_scipy
        import_scipy()      # without the numpy submodules scipy's namespace copy would import
        node = importlib.import_module(f"switchobs_ros.{module}")
        if participant_first:
            early.imported()    # garbage collection, off during the imports, on again
    except ModuleNotFoundError as err:
        if not (err.name or "").startswith("switchobs_msgs"):
            raise
        print(f"{prog}: error: {NO_MSGS}", file=sys.stderr)
        if participant_first:
            early.stop()
        return 2
    finally:
        signal.signal(signal.SIGINT, previous)
        if paused:
            try:
                gc.freeze()
            finally:
                gc.enable()
    return node.main()


def estimator() -> int:
    """``estimator``: :mod:`switchobs_ros.estimator`, its participant created first, its heap kept."""
    return _run("estimator", "estimator", participant_first=True, keep_heap=True, one_blas_thread=True)


def managed_estimator() -> int:
    """``managed_estimator``: :mod:`switchobs_ros.managed_estimator`, its heap kept."""
    return _run("managed_estimator", "managed_estimator", keep_heap=True, one_blas_thread=True)


def camera_sim() -> int:
    """``camera_sim``: :mod:`switchobs_ros.camera_sim`."""
    return _run("camera_sim", "camera_sim")


def switchobs_bag() -> int:
    """``switchobs_bag``: :mod:`switchobs_ros.bag.cli`."""
    return _run("bag.cli", "switchobs_bag", one_blas_thread=True, frozen_imports=True)
