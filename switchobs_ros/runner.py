"""The ``main`` of every node: the Jazzy demos' pattern, plus the project's start-up contract.

``rclpy.init``, build the node, spin; Ctrl-C or an external shutdown ends it with exit code 0; a
bad configuration (:class:`~switchobs_ros.params.ConfigError`, a parameter of the wrong type)
prints one line, ``<prog>: error: ...``, and exits 2. A signal while the node is still being
built (its context shut down under it) is a stop as well: exit 0, no traceback. A context the entry
point initialised already (the estimator's participant created before its imports,
:mod:`switchobs_ros.early`) is taken as it is, rclpy's signal handlers installed then. A second signal
during the clean-up (or one that arrives before the spin) must not turn the exit into a traceback
or a death by SIGINT: the clean-up swallows KeyboardInterrupt.
"""

from __future__ import annotations

import gc
import os
import sys

import rclpy
import rclpy.executors
from rclpy.exceptions import ParameterException
from rclpy.executors import ExternalShutdownException
from rclpy.signals import SignalHandlerOptions, install_signal_handlers

from switchobs_core.exceptions import one_line
from switchobs_core.threads import single_threaded_blas

from . import early, params_files
from .params import ConfigError
from .ros_args import with_float_lists

__all__ = ["make_executor", "run_node"]

#: ``SWITCHOBS_EXECUTOR``: ``kept`` (default), ``rclpy`` (rclpy's SingleThreadedExecutor) or ``events``
#: (rclpy's EventsExecutor, polled: :class:`~switchobs_ros.executor.PolledEventsExecutor`; for measurements).
EXECUTOR_ENV = "SWITCHOBS_EXECUTOR"


def make_executor():
    """The executor a node spins: :class:`~switchobs_ros.executor.KeptWaitSetExecutor` (one wait
    per wake-up of the middleware, the wait set kept between waits), or rclpy's
    SingleThreadedExecutor with ``SWITCHOBS_EXECUTOR=rclpy``, or rclpy's EventsExecutor with
    ``events`` (its ``spin()`` serves nothing with these wheels: spun by ``spin_once`` in a loop;
    it serves no guard condition and no callback group)."""
    kind = os.environ.get(EXECUTOR_ENV, "kept")
    if kind == "rclpy":
        return rclpy.executors.SingleThreadedExecutor()
    from .executor import KeptWaitSetExecutor, PolledEventsExecutor
    return PolledEventsExecutor() if kind == "events" else KeptWaitSetExecutor()


def _quiet_interrupt_in_finalizers(hook):
    """An ``sys.unraisablehook`` that drops a KeyboardInterrupt raised inside a finalizer.

    rclpy's SIGINT handler raises KeyboardInterrupt wherever the main thread is; when that is a
    ``__del__`` (e.g. rclpy's ``RcutilsLogger.__del__`` while the node is being built), Python
    cannot raise it and prints "Exception ignored in ... Traceback ... KeyboardInterrupt". The
    same signal has already shut the context down, so the node stops anyway (exit 0): the
    printout is noise. Every other unraisable exception goes to ``hook``.
    """
    def unraisable(u) -> None:
        if isinstance(u.exc_value, KeyboardInterrupt):
            return
        hook(u)
    return unraisable


def _quiet_shutdown() -> None:
    """Shut down a context the entry point initialised (:mod:`switchobs_ros.early`), a second
    Ctrl-C included."""
    try:
        early.stop()
    except KeyboardInterrupt:
        pass


def run_node(node_cls, prog: str, args=None) -> int:
    """Run ``node_cls()`` until shutdown; the process's exit code (see the module docstring)."""
    sys.unraisablehook = _quiet_interrupt_in_finalizers(sys.unraisablehook)
    try:
        single_threaded_blas()  # small matrices; see switchobs_core.threads (loads BLAS: a Ctrl-C may land here)
        argv = sys.argv if args is None else args
        params_files.GLOBAL_FILES[:] = params_files.params_files(argv)      # checked by declare_all
        if early.init_error is not None:    # the entry point's rclpy.init, from sys.argv, failed
            raise early.init_error
        if early.started():     # the entry point initialised the context (and its participant) from sys.argv
            install_signal_handlers(SignalHandlerOptions.ALL)
        else:
            rclpy.init(args=with_float_lists(argv))   # [1, 0.8]: doubles
    except KeyboardInterrupt:
        _quiet_shutdown()
        return 0
    except Exception as err:
        print(f"{prog}: error: cannot start ROS 2: {one_line(err)}", file=sys.stderr)
        return 2
    node = None
    code = 0
    try:
        node = node_cls()
        early.release()         # the node's own holds the participant now
        executor = make_executor()
        executor.add_node(node)
        if getattr(node, "gc_freeze", False):
            gc.freeze()     # start-up objects (tables, caches, messages) leave the collected generations
        executor.spin()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except (ConfigError, ParameterException) as err:
        print(f"{prog}: error: {one_line(err)}", file=sys.stderr)
        code = 2
    except Exception:
        if rclpy.ok():
            raise
        # a signal during start-up shut the context down under the node's constructor (e.g.
        # "failed to create timer: context is not valid"): that is a stop, not an error
        code = 0
    finally:
        try:
            early.release()
            if node is not None:
                node.destroy_node()
            rclpy.try_shutdown()
        except KeyboardInterrupt:
            pass
    return code or getattr(node, "exit_code", 0)
