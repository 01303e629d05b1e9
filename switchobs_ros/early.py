"""The estimator's DDS participant, created before its modules are imported (its console script's start).

A node's participant exists once the first node of its context does. The estimator's node is built
after about half a second of imports and its table's load, so without this DDS discovery (finding the
sensors' publishers, being found by their subscribers) would only start then: with Fast DDS's default
announcements (every 3 s) a start that misses the first exchange waits for the next one
(``bench/bench_startup.py``, bench/RESULTS.md). :func:`start`, called by :mod:`switchobs_ros.entry`
before it imports the node's module, initialises rclpy's default context from ``sys.argv`` and
creates a bare node in it (no parameter services, no rosout, no remapping), whose creation makes the
participant; discovery then runs during the imports. :func:`~switchobs_ros.runner.run_node` takes
that context instead of initialising one (:func:`started`) and destroys the bare node once the
estimator's node exists (:func:`release`).

Nothing here decides how a start ends: what ``rclpy.init`` raises (a bad ``--ros-args``) is kept
for ``run_node``, which refuses it in one line with its exit code as when it calls ``rclpy.init``
itself (:data:`init_error`); if the bare node cannot be created, the context is shut down again and
``run_node`` initialises it as it always does. The context is initialised without rclpy's signal handlers,
so the entry point's Ctrl-C handler (a quiet exit 0) stays in place during the imports; ``run_node``
installs rclpy's when it takes the context.

Message type support is imported without its code generator: rclpy imports each message's C
type support through ``rosidl_generator_py``, whose package also imports the generator of message
modules (``rosidl_generator_py.generate_py_impl``: ``rosidl_parser``'s grammar with ``lark``, ``em``,
``rosidl_pycommon``; 25-30 ms of a start's CPU) and carries on without it when that import fails.
:func:`start` imports the package with the generator's module marked absent, then removes the mark,
so that a later import of the generator in the same process gets the real one; nothing a node runs
generates message modules.

Garbage collection is off from :func:`start` until the node's module is imported (:func:`imported`,
called by the entry point): the imports otherwise make about 130 collections, 30-35 ms of a 32-agent
start's CPU, over objects that live as long as the process (modules, functions, classes). They are
then frozen (:func:`gc.freeze`, the order Python's documentation gives for objects made while
collection is off) and collection is on again before the node is built, so a table designed at
start-up is collected as usual, with the youngest generation collected every
:data:`BUILD_GEN0` allocations instead of 700 until the node exists (:func:`release` puts the
threshold back): 17 collections of a 32-agent build (2 ms) become one or two.
"""

from __future__ import annotations

import gc
import sys
from typing import Any

__all__ = ["imported", "release", "start", "started", "stop", "type_support_only"]

#: The module of ``rosidl_generator_py`` that generates message code (module docstring).
GENERATOR = "rosidl_generator_py.generate_py_impl"

_boot: Any = None       # the bare node holding the participant until the node's own exists
#: What ``rclpy.init`` raised in :func:`start` (``run_node`` reports it instead of initialising again).
init_error: Exception | None = None
_gc_paused = False      # start() turned garbage collection off; imported() turns it back on
_gc_threshold: tuple[int, ...] | None = None    # the thresholds imported() raised, release() restores
#: The youngest generation's collection threshold while the node is built (Python's default: 700).
BUILD_GEN0 = 20_000


def start(name: str) -> None:
    """Initialise rclpy's default context from ``sys.argv`` and create the bare node ``<name>_boot``;
    garbage collection off until :func:`imported`."""
    global _boot, init_error, _gc_paused
    if gc.isenabled():
        gc.disable()
        _gc_paused = True
    type_support_only()
    import rclpy
    from rclpy.signals import SignalHandlerOptions

    from .ros_args import with_float_lists
    try:
        rclpy.init(args=with_float_lists(sys.argv), signal_handler_options=SignalHandlerOptions.NO)
    except Exception as err:    # a bad --ros-args: run_node's one-line refusal, without a second attempt
        init_error = err
        return
    try:
        _boot = rclpy.create_node(f"{name}_boot", use_global_arguments=False, enable_rosout=False,
                                  start_parameter_services=False)
    except Exception:       # run_node initialises the context and reports what is wrong, as without this
        _boot = None
        try:
            rclpy.try_shutdown()
        except Exception:
            pass


def type_support_only() -> None:
    """Import ``rosidl_generator_py`` (rclpy's import of message type support) without its code
    generator (module docstring); nothing if it is imported already or not installed."""
    if "rosidl_generator_py" in sys.modules or GENERATOR in sys.modules:
        return
    sys.modules[GENERATOR] = None       # its package's ``from .generate_py_impl import ...`` fails
    try:
        import rosidl_generator_py  # noqa: F401
    except ImportError:
        pass
    finally:
        if GENERATOR in sys.modules and sys.modules[GENERATOR] is None:
            del sys.modules[GENERATOR]


def imported() -> None:
    """The node's module is imported: what the imports made frozen, garbage collection on again (if
    :func:`start` turned it off)."""
    global _gc_paused, _gc_threshold
    if _gc_paused:
        _gc_paused = False
        gc.freeze()
        _gc_threshold = gc.get_threshold()
        gc.set_threshold(max(BUILD_GEN0, _gc_threshold[0]), *_gc_threshold[1:])
        gc.enable()


def started() -> bool:
    """Whether :func:`start` left an initialised context (with its bare node) for ``run_node``."""
    return _boot is not None


def release() -> None:
    """Destroy the bare node (the node's own holds the participant now), nothing if there is none; the
    garbage collector's thresholds as before :func:`imported`."""
    global _boot, _gc_threshold
    if _gc_threshold is not None:
        gc.set_threshold(*_gc_threshold)
        _gc_threshold = None
    boot, _boot = _boot, None
    if boot is not None:
        try:
            boot.destroy_node()
        except Exception:       # the context was shut down under it (a signal): nothing left to free
            pass


def stop() -> None:
    """:func:`release`, then shut the context down (a start that ends before ``run_node`` takes it)."""
    if _boot is not None:
        import rclpy
        release()
        rclpy.try_shutdown()
