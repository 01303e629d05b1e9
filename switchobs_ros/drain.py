"""The estimator's input callbacks take the input messages already waiting, and those about to come.

Every wait of the executor costs Python and middleware work (rclpy's SingleThreadedExecutor
rebuilds its wait set for it, about 150 us for the estimator;
:class:`~switchobs_ros.executor.KeptWaitSetExecutor`, the node's, keeps it: about a third of that;
bench/RESULTS.md), and live at 32 agents a wake-up of the node's thread with its wait, take and
dispatch costs about 0.3 ms of CPU with the caches cold. :func:`drain_inputs` takes, after a
callback, the input messages already waiting (channel, camera, target: one of each per round, the
channel first, as the executor orders them after one wait) and handles them, up to
``DRAIN_MAX``: the target pose that arrives while the camera pose is handled would cost one more
wait, and a backlog one wait per message.

A sender publishes a tick's messages one after another (camera_sim: the channel, then each
pose), a few tens of microseconds apart, and the node wakes at the first. When nothing more is
waiting but a part of the tick is surely on its way (the last message handled was the channel's,
or a pending sample lacks a source's part), :func:`linger` polls the inputs for up to
:data:`LINGER_S` (yielding the processor between polls, so that a sender on the same core runs)
instead of returning to a wait: at most :data:`LINGERS` times per callback. Nothing else changes:
the messages are handled in the order they are taken, by the same handlers.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable, Sequence
from typing import Any

from rclpy.exceptions import InvalidHandle

__all__ = ["LINGER_S", "LINGERS", "drain_inputs", "linger"]

#: How long one linger polls the inputs (s, wall clock), and how many lingers per callback.
LINGER_S = 150e-6
LINGERS = 2


def _take(sub: Any) -> Any:
    with sub.handle:
        return sub.handle.take_message(sub.msg_type, sub.raw)


def linger(hot: Sequence[tuple[Any, Callable]], budget_s: float, clock: Callable[[], float] = time.perf_counter,
           take: Callable[[Any], Any] = _take) -> tuple[Callable, Any] | None:
    """Poll the input subscriptions ``hot`` (``(subscription, handler)``, in order) for up to
    ``budget_s``: ``(handler, (message, info))`` of the first message taken, None when none came."""
    end = clock() + budget_s
    while True:
        for sub, handle in hot:
            got = take(sub)
            if got is not None:
                return handle, got
        if clock() >= end:
            return None
        os.sched_yield()


def part_on_its_way(node: Any, last: Callable | None) -> bool:
    """Whether a part of the sample being assembled is surely still to come: the last message
    handled was the channel's (its tick's poses follow it), or a pending sample lacks a source."""
    if last is not None and getattr(last, "is_channel", False):
        return True
    pl = node.pipeline
    n = len(pl.sources)
    return any(len(p.parts) < n for p in pl.pairing.pending.values())


def drain_inputs(node: Any, last: Callable | None = None) -> None:
    """Take and handle the input messages waiting, and those :func:`linger` catches (module
    docstring); then drop the executor's queued entries of the inputs (``discard_ready``: each would
    cost an empty take; an input that holds a message again is reported by the next wait, rcl's
    wait being level-triggered) and arm the pairing timer if a sample waits. ``last``: the handler
    of the message the callback handled."""
    hot = node._hot_inputs
    n = lingers = 0
    budget = node.LINGER_S
    try:
        while n < node.DRAIN_MAX:
            took = n
            for sub, handle in hot:
                try:
                    got = _take(sub)
                except InvalidHandle:       # destroyed (managed node cleanup)
                    return
                if got is not None:
                    handle(got[0], got[1])
                    last = handle
                    n += 1
            if n == took:
                if lingers >= LINGERS or budget <= 0 or not part_on_its_way(node, last):
                    break
                lingers += 1
                try:
                    caught = linger(hot, budget)
                except InvalidHandle:
                    return
                if caught is None:
                    break
                last, got = caught
                last(got[0], got[1])
                n += 1
        discard = getattr(getattr(node, "executor", None), "discard_ready", None)
        if discard is not None:
            discard(tuple(h[0] for h in node._hot_inputs))
        node._arm_pairing_timer()
    except Exception as err:
        node.pipeline.internal_error("input", err)
