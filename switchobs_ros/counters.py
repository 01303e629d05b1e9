"""The estimator's counters: what it accepted, rejected and answered, and whether its bounds stand.

Diagnostics (:mod:`switchobs_ros.diagnostics`) and ``switchobs_bag estimate`` report them; none is
ever cleared. A rejected message is counted under ``(topic, reason)`` (the reasons of
:class:`msg_bridge.Reason`); an accepted message that no estimate used is counted in ``dropped``
by reason, so nothing is dropped silently.
"""

from __future__ import annotations

import traceback
from collections import Counter

from msg_bridge import Rejection

__all__ = ["NO_BOUND", "Counters", "PipelineLog"]

#: ``exact_bound`` published after a reset: no bound is known any more. ``||Phi(t, t0)|| e0`` holds
#: only if ``||x_hat(t0) - x(t0)|| <= e0`` at the time origin; the configured ``e0`` is the user's
#: claim for the start, but after a reset (``~/reset``, a clock jump back, a non-finite estimate)
#: the plant has moved on and nothing bounds the new initial error. -1 is finite (the node never
#: publishes non-finite values) and cannot be a norm bound.
NO_BOUND = -1.0


class PipelineLog:
    """Where the pipeline reports: ``info``/``warn``/``error`` (text, throttle).

    ``throttle`` marks messages that may repeat at the input rate (the node throttles them to
    one per second). The default discards everything (offline use).
    """

    def info(self, text: str) -> None:
        pass

    def warn(self, text: str, throttle: bool = False) -> None:
        pass

    def error(self, text: str, throttle: bool = False) -> None:
        pass


class Counters:
    """The counters of :class:`~switchobs_ros.pipeline.EstimatorPipeline` (its attributes).

    ``accepted`` (per input topic), ``rejected`` (per ``(topic, reason)``), ``dropped`` (accepted
    messages no update used, per reason), ``updates``, ``partial_updates``, ``parts_used``
    (accepted messages an update consumed), ``switches``, ``resets``, ``states_set``, ``errors``,
    ``nonfinite`` (estimates withheld because not finite, each followed by a reset),
    ``inconsistent``, ``reattributed``, ``lost_channel_named`` (samples sent while channel
    messages were lost whose channel the consistency test named), ``near_switch`` (samples stamped within
    the clock tolerance of a switching instant whose channel rows were dropped), ``uncertain`` and
    ``uncertain_named`` (samples whose channel was not proven within the reorder window: channel rows
    dropped, or the channel named by the consistency test), ``outliers`` (the chi-square
    gate); ``last_rejection`` and ``last_inconsistency`` are the latest texts. ``bound_valid`` is
    False once the bounds are withdrawn (:data:`NO_BOUND` is published), ``bound_invalid_why``
    says why; ``recertifications`` counts the bounds certified again from data
    (:mod:`switchobs_core.runtime.recovery`), ``bound_note`` says since when while they hold;
    ``bias_alarms`` and ``model_failures`` (bodies the chi-square gate starved) count the recovery's
    alarms, ``last_alarm`` is the latest one's text.
    """

    def __init__(self, log: PipelineLog):
        self.log = log
        self.accepted: Counter = Counter()
        self.rejected: Counter = Counter()
        self.dropped: Counter = Counter()
        self.updates = 0
        self.partial_updates = 0
        self.parts_used = 0
        self.switches = 0
        self.resets = 0
        self.states_set = 0
        self.errors = 0
        self.nonfinite = 0
        self.inconsistent = 0
        self.reattributed = 0
        self.lost_channel_named = 0
        self.near_switch = 0
        self.uncertain = 0
        self.uncertain_named = 0
        self.outliers = 0
        self.last_rejection = ""
        self.last_inconsistency = ""
        self.bound_valid = True
        self.bound_invalid_why = ""
        self.recertifications = 0
        self.recertified = ""       # how and since when the bounds were last certified from data
        self.bias_alarms = 0
        self.model_failures = 0
        self.last_alarm = ""

    def reject(self, topic: str, rej: Rejection) -> None:
        """Count a rejected message under ``(topic, reason)``."""
        self.rejected[(topic, rej.reason.value)] += 1
        self.last_rejection = f"{topic}: {rej}"
        self.log.warn(f"rejected {topic}: {rej}", throttle=True)

    def reject_all(self, topics: list[str], rej: Rejection) -> None:
        """Reject the parts of one sample (one message per topic) and count them as dropped."""
        for t in topics:
            self.reject(t, rej)
        self.dropped[rej.reason.value] += len(topics)

    def internal_error(self, where: str, err: Exception) -> None:
        """Count an exception raised while handling an input (the caller keeps running)."""
        self.errors += 1
        self.rejected[(where, "internal_error")] += 1
        self.last_rejection = f"{where}: internal_error: {type(err).__name__}: {err}"
        tb = traceback.extract_tb(err.__traceback__)
        at = f" (at {tb[-1].filename.rsplit('/', 1)[-1]}:{tb[-1].lineno})" if tb else ""
        self.log.error(f"{where}: {type(err).__name__}: {err}{at}", throttle=True)

    def withdraw(self, why: str) -> None:
        """No bound can be guaranteed any more: publish :data:`NO_BOUND` until :meth:`recertify` or a reset."""
        if self.bound_valid:
            self.log.error(f"bounds withdrawn: {why}")
        self.bound_valid = False
        self.bound_invalid_why = why

    @property
    def bound_note(self) -> str:
        """While the bounds hold after a re-certification: how and since when (else "")."""
        return self.recertified if self.bound_valid else ""

    def recertify(self, text: str) -> None:
        """The bounds hold again, certified from data (``text``: since when, from which window)."""
        self.recertifications += 1
        self.recertified = text
        self.bound_valid = True
        self.bound_invalid_why = ""
        self.log.info(f"bounds {text}")
