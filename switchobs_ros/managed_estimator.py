"""The estimator as a managed (lifecycle) node: ``ros2 run switchobs_ros managed_estimator``.

Same parameters, topics and behaviour as :mod:`switchobs_ros.estimator` (the shared
:class:`~switchobs_ros.estimator.EstimatorMixin`), driven by the ROS 2 lifecycle
(``~/change_state``, ``~/get_state``, ... from ``lifecycle_msgs``):

* **configure** loads (or designs and caches) the gain table and builds the observer, then the
  publishers, subscriptions, timers and ``~/reset``. A failure (a bad parameter value, a table
  that does not load, a design that fails) leaves the node *unconfigured*: the transition
  returns FAILURE, the reason is logged as one error line and kept in :attr:`last_failure`.
* **activate** starts answering measurements.
* **deactivate** stops answering without losing the estimate: measurements are ignored (and
  counted); after activate the observer propagates exactly over the gap at the next sample.
* **cleanup** and **shutdown** release the interfaces and the observer.

A transition that is not valid in the current state (``activate`` while unconfigured, the second
of two requests that arrive together) returns FAILURE, logs the reason as one error line (kept in
:attr:`last_failure`) and leaves the node in its state; rclpy raised an ``RCLError`` ("Transition
is not registered") that killed the node with a traceback. Transitions run one at a time (a lock:
the service and the ``trigger_*`` methods share it, whatever the executor).

``autostart`` (default true) configures and activates at start-up, which is the plain
estimator's behaviour; a failed autostart configure exits with the one-line error and code 2,
as the plain estimator does. ``autostart:=false`` waits for the lifecycle services.
"""

from __future__ import annotations

import sys

if __name__ == "__main__":      # python -m switchobs_ros.managed_estimator: the console script's start, heap kept
    from switchobs_ros.entry import managed_estimator as _console_script
    sys.exit(_console_script())

import threading
import time

from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.lifecycle import LifecycleNode, LifecycleState, TransitionCallbackReturn
from rclpy.lifecycle.node import LifecycleNodeMixin

from switchobs_core.exceptions import SwitchobsError, one_line

from .config import PARAMS
from .estimator import EstimatorMixin
from .log_callers import register_log_callers
from .params import ConfigError, declare_all
from .runner import run_node

__all__ = ["ManagedEstimatorNode", "main"]


class ManagedEstimatorNode(EstimatorMixin, LifecycleNode):
    """The estimator under the ROS 2 lifecycle (module docstring)."""

    def __init__(self, **kwargs):
        self._transition_lock = threading.RLock()
        super().__init__("estimator", **kwargs)
        self.t_start = time.monotonic()
        register_log_callers("switchobs_ros.estimator", __name__)
        self.cfg = declare_all(self, PARAMS, gated=True)
        self.answering = False
        self.configured = False
        self.last_failure = ""
        self.add_on_set_parameters_callback(self._on_set_parameters_if_configured)
        if self.cfg["autostart"]:
            self.trigger_configure()
            if not self.configured:
                raise ConfigError(self.last_failure)
            self.trigger_activate()

    def _on_set_parameters_if_configured(self, params: list):
        from rcl_interfaces.msg import SetParametersResult

        if not self.configured:
            return SetParametersResult(successful=False, reason="configure the node first (lifecycle)")
        return self._on_set_parameters(params)

    # ------------------------------------------------------------------ transitions
    def _LifecycleNodeMixin__change_state(self, transition_id: int) -> TransitionCallbackReturn:
        """Every transition (``~/change_state`` and ``trigger_*``) comes here: serialised, and
        checked against the transitions valid in the current state (module docstring)."""
        with self._transition_lock:
            sm = self._state_machine
            state = sm.current_state[1]
            valid = {t[0] for t in sm.available_transitions}
            if transition_id not in valid:
                names = {t[0]: t[1] for t in sm.transition_graph}
                return self._refuse(f"transition '{names.get(transition_id, transition_id)}' is not valid in state "
                                    f"'{state}' (valid: {', '.join(sorted({names[t] for t in valid})) or 'none'}); "
                                    f"the node stays {state}")
            try:
                return LifecycleNodeMixin._LifecycleNodeMixin__change_state(self, transition_id)
            except _rclpy.RCLError as err:      # the state machine refused after all
                return self._refuse(f"transition {transition_id} from state '{state}' failed: {one_line(err)}")

    def _refuse(self, why: str) -> TransitionCallbackReturn:
        self.last_failure = why
        self.get_logger().error(why)
        return TransitionCallbackReturn.FAILURE

    def on_configure(self, state: LifecycleState) -> TransitionCallbackReturn:
        try:
            self._configure(self.cfg)
            self._create_interfaces()
        except (SwitchobsError, ValueError) as err:
            self.last_failure = one_line(err)
            self.get_logger().error(f"configure failed: {self.last_failure}")
            self._release()
            return TransitionCallbackReturn.FAILURE
        self.configured = True
        self.last_failure = ""
        self._ready_log()
        return TransitionCallbackReturn.SUCCESS

    def on_activate(self, state: LifecycleState) -> TransitionCallbackReturn:
        self.answering = True
        self.get_logger().info("activated: answering measurements")
        return super().on_activate(state)

    def on_deactivate(self, state: LifecycleState) -> TransitionCallbackReturn:
        self.answering = False
        self.get_logger().info("deactivated: measurements are ignored; the estimate is kept")
        return super().on_deactivate(state)

    def on_cleanup(self, state: LifecycleState) -> TransitionCallbackReturn:
        self._release()
        self.get_logger().info("cleaned up: observer and interfaces released")
        return TransitionCallbackReturn.SUCCESS

    def on_shutdown(self, state: LifecycleState) -> TransitionCallbackReturn:
        self._release()
        return TransitionCallbackReturn.SUCCESS

    def _release(self) -> None:
        self.answering = False
        self.configured = False
        self._destroy_interfaces()
        self.pipeline = self.observer = None


def main(args=None) -> int:
    return run_node(ManagedEstimatorNode, "managed_estimator", args)
