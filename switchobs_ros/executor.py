"""A single-threaded rclpy executor that keeps its wait set between waits.

rclpy's :class:`~rclpy.executors.SingleThreadedExecutor` rebuilds its wait set in Python for every
callback it runs (it gathers the nodes' entities, enters each handle, allocates an rcl wait set,
and wraps the callback in a :class:`~rclpy.task.Task`), and every callback it runs triggers the
executor's own guard condition, so the next wait returns at once with nothing but that guard
ready: two waits per callback. :class:`KeptWaitSetExecutor` builds the entity lists and the rcl
wait set once, again only after :meth:`wake` (rclpy's nodes call it when they create or destroy an
entity), and calls each ready callback directly: one wait per wake-up of the middleware. Inside
:meth:`~KeptWaitSetExecutor.spin` the handles of that wait set also stay entered (rclpy's use count,
which defers a destruction) from one wait to the next, instead of 2 x 22 enter and exit calls per
wait for the estimator. An entity destroyed while they are held is destroyed as rclpy's executor
destroys it: by a callback or by another thread while the spinner runs a callback, at once (the
handles are released in :meth:`~KeptWaitSetExecutor.wake`, so that the destroying thread can
subscribe to the topic with another type); by another thread during a wait, as soon as that wait
returns (rclpy's executor holds its handles during a wait too). All are released when ``spin``
returns.

It serves what rclpy's executor serves, in the same order per wait (timers, subscriptions, guard
conditions, clients, services, then waitables, each in its node's creation order) and one ready
entity per :meth:`spin_once`: subscriptions (plain and raw, with or without ``MessageInfo``),
timers (cancelled timers never fire), services (``~/reset``, the parameter services, the
lifecycle services), clients, the nodes' guard conditions, waitables (middleware event handlers),
the executor's own guard condition (:meth:`wake`, :meth:`shutdown`) and the SIGINT guard
condition. A coroutine callback, a waitable's ``execute`` and a future's done callbacks become
rclpy :class:`~rclpy.task.Task` objects, run here a step per :meth:`spin_once` as rclpy's
executor runs them. Clock jumps are rcl's own callbacks, run inside the ``/clock`` subscription's
callback. Shutdown: :meth:`shutdown` or the context's shutdown (Ctrl-C) wakes the wait;
:meth:`spin` then returns, or raises :class:`~rclpy.executors.ExternalShutdownException` as
rclpy's executor does.

Single-threaded only: a callback group's ``beginning_execution`` is still asked, so a callback
that spins this executor again cannot re-enter a mutually exclusive group.
"""

from __future__ import annotations

import inspect
import itertools
import operator
import threading
import weakref
from collections import deque
from typing import Any

from rclpy.event_handler import EventHandler
from rclpy.exceptions import InvalidHandle
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor, TimeoutObject
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.subscription import Subscription
from rclpy.utilities import timeout_sec_to_nsec
from rclpy.waitable import NumberOfEntities

__all__ = ["KeptWaitSetExecutor", "PolledEventsExecutor"]

_TIMER, _SUB, _GUARD, _CLIENT, _SERVICE, _WAITABLE = range(6)


class _Plan:
    """The entities of the executor's nodes, their handles, and the rcl wait set sized for them.

    What each wait repeats is prepared here once: ``adds``, the wait set's adder and the handle of
    each entity in rclpy's order (the executor's own guard conditions last), so that a wait reads no
    ``handle`` property and dispatches on no kind; ``waitables``, each waitable with, for an rclpy
    ``EventHandler`` (the middleware's QoS events of publishers and subscriptions), the event handle
    it adds, entered and added directly (:func:`_event_of`; None: any other waitable, served through
    the Waitable API); ``index``, each entity's place in that order by the pointer the wait set
    reports it ready by (``kinds``: the entity kinds present), so that a wait looks up the few ready
    entities instead of testing every entity."""

    __slots__ = ("entities", "adds", "waitables", "wait_set", "index", "kinds", "live", "live_waitables", "entered",
                 "gen")

    def __init__(self, executor: KeptWaitSetExecutor) -> None:
        timers, subs, guards, clients, services, waitables = [], [], [], [], [], []
        for node in executor.get_nodes():
            timers += [(_TIMER, t, node) for t in node.timers]
            subs += [(_SUB, s, node) for s in node.subscriptions]
            guards += [(_GUARD, g, node) for g in node.guards]
            clients += [(_CLIENT, c, node) for c in node.clients]
            services += [(_SERVICE, s, node) for s in node.services]
            waitables += [(_WAITABLE, w, node) for w in node.waitables]
        own = [g for g in (executor._guard, executor._sigint_gc) if g is not None]
        self.entities = timers + subs + guards + clients + services
        count = NumberOfEntities(len(subs), len(guards) + len(own), len(timers), len(clients), len(services))
        for _, w, _ in waitables:
            count += w.get_num_entities()
        with executor._context.handle:
            ws = self.wait_set = _rclpy.WaitSet(count.num_subscriptions, count.num_guard_conditions,
                                                count.num_timers, count.num_clients, count.num_services,
                                                count.num_events, executor._context.handle)
        adder = {_TIMER: ws.add_timer, _SUB: ws.add_subscription, _GUARD: ws.add_guard_condition,
                 _CLIENT: ws.add_client, _SERVICE: ws.add_service}
        self.adds = [(adder[e[0]], e[1].handle) for e in self.entities] + \
                    [(ws.add_guard_condition, g.handle) for g in own]
        self.waitables = [(item, _event_of(item[1])) for item in waitables]
        self.index: dict[str, dict[int, int]] = {}
        for i, e in enumerate(self.entities):
            try:
                self.index.setdefault(_KINDS[e[0]], {})[e[1].handle.pointer] = i
            except InvalidHandle:      # destroyed since: left out of the waits
                pass
        self.kinds = tuple(self.index.items())
        self.live: list = []
        self.live_waitables: list = []
        self.entered: list = []
        self.gen = 0        # the executor's change number when this plan was built

    def enter(self) -> None:
        """Enter every handle (rclpy's use count: a handle destroyed meanwhile is destroyed only
        once it is released); ``live``, the adds of those entered, ``live_waitables`` the waitables
        entered (a handle destroyed already is left out). Interrupted (any exception), it exits the
        handles it entered before re-raising."""
        entered: list = []
        try:
            live = [(add, h) for add, h in self.adds if _enter(h, entered)]
            live_waitables = [(item, ev) for item, ev in self.waitables
                              if _enter(item[1] if ev is None else ev, entered)]
        except BaseException:
            _exit_all(entered)
            raise
        self.entered, self.live, self.live_waitables = entered, live, live_waitables

    def release(self) -> None:
        """Exit the handles :meth:`enter` entered (last first), every one of them also when an
        exception comes between two exits (:func:`_exit_all`). They are exited from
        :attr:`entered` itself: an interrupted release leaves there what a later one exits."""
        self.live, self.live_waitables = [], []
        _exit_all(self.entered)


#: ``h.__exit__(None, None, None)``, called from C (:func:`_exit_all`).
_EXIT = operator.methodcaller("__exit__", None, None, None)


def _exit_all(handles: list) -> None:
    """Exit every handle of ``handles`` (last first), each popped from the list as it is exited. An
    exception between two exits or from one (a KeyboardInterrupt: Python runs the signal's handler
    between two bytecodes) does not leave the rest entered, which would hold their destruction off
    for good: they are exited before it propagates (a second exception meanwhile likewise). The pops
    and the exits run in one C loop (``deque`` over ``map`` over ``iter(handles.pop, ...)``), so no
    bytecode lies between a handle's pop and its exit where a signal's handler could run: a handle
    off the list is one being exited (``pop`` ends the loop with IndexError when the list is empty)."""
    try:
        deque(map(_EXIT, iter(handles.pop, None)), maxlen=0)
    except IndexError:
        if handles:                 # not the end of the list: an exit raised it
            raise
    finally:
        if handles:
            _exit_all(handles)


def _enter(handle: Any, entered: list) -> bool:
    """Enter ``handle`` and append it to ``entered``; False if it is destroyed already."""
    try:
        handle.__enter__()
    except InvalidHandle:
        return False
    entered.append(handle)
    return True


_KINDS = {_TIMER: "timer", _SUB: "subscription", _GUARD: "guard_condition", _CLIENT: "client", _SERVICE: "service"}


_OWN = ("__enter__", "__exit__", "add_to_wait_set", "is_ready", "take_data")


def _event_of(waitable: Any) -> Any:
    """The event handle of an rclpy ``EventHandler`` whose Waitable methods are rclpy's own (a QoS
    event of a publisher or subscription), else None (the waitable is served through its methods).

    Such a handler's ``__enter__``, ``add_to_wait_set`` and ``__exit__`` only enter, add and exit
    this handle and keep the index ``add_event`` returns (``_event_index``); its ``is_ready`` asks
    the wait set about that index and records the answer (``_ready_to_take_data``) for its
    ``take_data``: the executor does the same itself, without four Python calls per handler and
    wait."""
    cls = type(waitable)
    if not isinstance(waitable, EventHandler) or any(getattr(cls, m) is not getattr(EventHandler, m) for m in _OWN):
        return None
    return getattr(waitable, "_EventHandler__event", None)


class KeptWaitSetExecutor(SingleThreadedExecutor):
    """rclpy's single-threaded executor with a wait set kept between waits (module docstring).

    :attr:`waits` counts the waits, :attr:`calls` the callbacks run, :attr:`rebuilds` the times
    the wait set was built."""

    def __init__(self, *, context=None) -> None:
        super().__init__(context=context)
        self._plan: _Plan | None = None
        # every change of the entity set takes a new number (next() of a count is atomic): a plan built
        # after reading the number _changes held is rebuilt once it holds another
        self._gen = itertools.count(1)
        self._changes = 0
        self._ready: deque = deque()
        self._entered: _Plan | None = None      # the plan whose handles are entered
        self._holding = False                   # inside spin(): handles kept entered between waits
        self._in_wait = False
        # guards the spinner's entering (up to _in_wait = True) and its release after a wait
        # against wake() from another thread; _release_after_wait: a wake came during the wait
        self._hold_lock = threading.Lock()
        self._release_after_wait = False
        self.waits = 0
        self.calls = 0
        self.rebuilds = 0

    # -------------------------------------------------------------- changes of the entity set
    def wake(self) -> None:
        """Rebuild the wait set before the next wait (an entity was created or destroyed) and wake
        the current wait. Outside a wait (called by a callback, or by another thread while the
        spinner runs a callback) the held handles are released at once: a destroyed entity is
        destroyed now, as rclpy's executor would, so that the caller can create another on its
        topic (of another type); during a wait they are released as soon as the wait returns."""
        self._changes = next(self._gen)
        with self._hold_lock:
            if self._in_wait:
                self._release_after_wait = True
            else:
                self._release()
        super().wake()

    def add_node(self, node) -> bool:
        added = super().add_node(node)
        self._changes = next(self._gen)     # after the node is in the list the next plan reads
        return added

    def remove_node(self, node) -> None:
        super().remove_node(node)
        self._changes = next(self._gen)

    def shutdown(self, timeout_sec: float | None = None) -> bool:
        self._plan = None
        self._ready.clear()
        return super().shutdown(timeout_sec)

    # -------------------------------------------------------------- spinning
    def spin(self) -> None:
        """rclpy's ``spin``, with the handles of the wait set entered once for as long as it spins
        (and the wait set is not rebuilt) rather than entered and exited around every wait; they
        are released when it returns, and when an entity is created or destroyed (:meth:`wake`:
        outside a wait at once, during a wait as soon as it returns). rclpy destroys a handle whose
        destruction was asked for once it is released."""
        self._holding = True
        try:
            super().spin()
        finally:
            with self._hold_lock:
                self._holding = False
                self._release()

    def _release(self) -> None:
        plan = self._entered
        if plan is not None:        # interrupted, the plan stays: the next release exits what is left
            plan.release()
        self._entered = None

    def spin_once(self, timeout_sec: float | None = None) -> None:
        """Run one ready callback (and one step of each pending task), waiting up to ``timeout_sec``
        (None: no limit) when none is ready."""
        if self._is_shutdown:
            return
        if self._tasks and self._run_tasks():
            timeout_sec = 0.0        # a task waits for something: poll, as rclpy's executor does
        while not self._ready:
            if not self._wait(timeout_sec):
                return
        self._serve(self._ready.popleft())

    def discard_ready(self, subscriptions: tuple) -> None:
        """Drop the queued ready entries of these subscriptions: a callback took their messages
        (:meth:`EstimatorMixin._drain_inputs <switchobs_ros.estimator.EstimatorMixin._drain_inputs>`).
        Nothing is lost: one that holds a message again is reported ready by the next wait."""
        queue = self._ready
        if queue and any(item[0] == _SUB and item[1] in subscriptions for item in queue):
            kept = [item for item in queue if not (item[0] == _SUB and item[1] in subscriptions)]
            queue.clear()
            queue.extend(kept)

    def spin_once_until_future_complete(self, future, timeout_sec=None) -> None:
        if isinstance(timeout_sec, TimeoutObject):
            timeout_sec = timeout_sec.timeout
        if not future.done():
            self.spin_once(timeout_sec)

    def _run_tasks(self) -> bool:
        """One step of every task not running (rclpy's order: newest first); True if some remain."""
        with self._tasks_lock:
            tasks = list(self._tasks)
        for task, _, _ in reversed(tasks):
            if not task.executing() and not task.done():
                task()
        with self._tasks_lock:
            self._tasks = [t for t in self._tasks if not t[0].done() and not t[0].cancelled()]
            return bool(self._tasks)

    def _wait(self, timeout_sec: float | None) -> bool:
        """One wait; the ready entities queued in rclpy's order. False on timeout or shutdown."""
        with self._hold_lock:
            plan = self._plan
            if plan is None or plan.gen != self._changes:
                self._release()
                gen = self._changes                 # read before the nodes' entities are
                plan = self._plan = _Plan(self)
                plan.gen = gen
                self.rebuilds += 1
            if self._entered is not plan:
                self._release()
                plan.enter()
                self._entered = plan
            self._in_wait = True
        ws = plan.wait_set
        try:
            ws.clear_entities()
            for add, h in plan.live:
                add(h)
            add_event = ws.add_event
            live = []
            for item, ev in plan.live_waitables:
                w = item[1]
                if ev is None:
                    w.add_to_wait_set(ws)
                    live.append((item, None))
                else:
                    w._event_index = idx = add_event(ev)
                    live.append((item, idx))
            self.waits += 1
            ws.wait(timeout_sec_to_nsec(timeout_sec))
            if self._is_shutdown:
                return False
            if not self._context.ok():
                raise ExternalShutdownException()
            ready = []
            for kind, where in plan.kinds:
                for p in ws.get_ready_entities(kind):
                    i = where.get(p)
                    if i is not None:
                        ready.append(i)
            queue = self._ready
            if ready:
                if len(ready) > 1:
                    ready.sort()
                entities = plan.entities
                queue.extend(entities[i] for i in ready)
            is_ready = ws.is_ready
            for item, idx in live:
                w = item[1]
                if idx is None:
                    if not w.is_ready(ws):
                        continue
                elif is_ready("event", idx):
                    w._ready_to_take_data = True        # what its is_ready records for take_data
                else:
                    continue
                queue.append(item + (w.take_data(),))
        finally:
            with self._hold_lock:
                self._in_wait = False
                if self._release_after_wait or not self._holding:
                    self._release_after_wait = False
                    self._release()
        return bool(self._ready) or timeout_sec is None or timeout_sec < 0

    def _serve(self, item: tuple) -> None:
        """Run the callback of one ready entity (taking its message, request or response first)."""
        kind, ent = item[0], item[1]
        group = ent.callback_group
        if group is not None and not group.beginning_execution(ent):
            return
        try:
            if kind == _SUB:
                try:
                    with ent.handle:
                        got = ent.handle.take_message(ent.msg_type, ent.raw)
                except InvalidHandle:
                    return
                if got is None:         # taken already (e.g. by a callback that drains its inputs)
                    return
                if ent._callback_type is Subscription.CallbackType.MessageOnly:
                    self._call(ent.callback, got[0])
                else:
                    self._call(ent.callback, got[0], got[1])
            elif kind == _TIMER:
                try:
                    with ent.handle:
                        if not ent.handle.is_timer_ready():     # cancelled, or reset since the wait
                            return
                        ent.handle.call_timer()
                except InvalidHandle:
                    return
                self._call(ent.callback)
            elif kind == _SERVICE:
                try:
                    with ent.handle:
                        request, header = ent.handle.service_take_request(ent.srv_type.Request)
                except InvalidHandle:
                    return
                if header is not None:
                    self._respond(ent, request, header)
            elif kind == _GUARD:
                ent._executor_triggered = False
                if ent.callback is not None:
                    self._call(ent.callback)
            elif kind == _CLIENT:
                self._client_response(ent)
            else:
                for future in ent._futures:
                    future._set_executor(self)
                self.create_task(ent.execute, item[3])
        finally:
            if group is not None:
                group.ending_execution(ent)

    def _call(self, callback, *args: Any) -> None:
        """A callback, or, for a coroutine function, a task that rclpy's machinery steps."""
        self.calls += 1
        if inspect.iscoroutinefunction(callback):
            self.create_task(callback, *args)
        else:
            callback(*args)

    def _respond(self, srv, request, header) -> None:
        self.calls += 1
        if inspect.iscoroutinefunction(srv.callback):
            async def answer():
                srv.send_response(await srv.callback(request, srv.srv_type.Response()), header)
            self.create_task(answer)
        else:
            srv.send_response(srv.callback(request, srv.srv_type.Response()), header)

    def _client_response(self, client) -> None:
        try:
            with client.handle:
                header, response = client.handle.take_response(client.srv_type.Response)
        except InvalidHandle:
            return
        if header is None:
            return
        self.calls += 1
        try:
            future = client.get_pending_request(header.request_id.sequence_number)
        except KeyError:        # the request was cancelled
            return
        future._set_executor(self)
        future.set_result(response)


class PolledEventsExecutor:
    """rclpy's ``rclpy.experimental.EventsExecutor`` spun by ``spin_once(timeout)`` in a loop.

    Its ``spin()`` (no timeout) waits on a condition variable until ``steady_clock::time_point::max()``;
    in these wheels ``std::condition_variable`` keeps time on the system clock, the deadline's
    conversion overflows into the past, and the wait returns at once, forever: the spinning thread
    busy-loops holding the queue's mutex and the middleware's listener threads, which enqueue
    every message and timer event under that mutex, starve (no callback at all:
    bench/events_executor_check.py). A finite timeout converts without overflow.

    It also calls a subscription callback that takes rclpy's ``MessageInfo`` with one argument,
    the ``(message, info)`` tuple (a TypeError, reported as "SystemError: null argument to
    internal routine"): such callbacks are wrapped here to unpack the tuple. Guard conditions and
    callback groups are not served by that executor (rclpy's own limits).
    """

    #: The timeout of each ``spin_once`` (s): also how soon a shutdown is noticed.
    POLL = 0.5

    def __init__(self, *, context=None) -> None:
        from rclpy.experimental import EventsExecutor
        from rclpy.utilities import get_default_context
        self._context = context or get_default_context()
        self._ex = EventsExecutor(context=self._context)
        self._stop = False

    @staticmethod
    def _unpack_message_info(node) -> None:
        """Wrap each callback of ``node`` that takes MessageInfo to take the one tuple instead."""
        for sub in node.subscriptions:
            if sub._callback_type is Subscription.CallbackType.WithMessageInfo and \
                    not getattr(sub._callback, "unpacks_message_info", False):
                def unpack(msg_info, fn=sub._callback):
                    return fn(*msg_info)
                unpack.unpacks_message_info = True
                sub._callback = unpack      # the callback type stays WithMessageInfo

    def add_node(self, node) -> bool:
        self._unpack_message_info(node)
        added = self._ex.add_node(node)
        # the node's entity changes (Node._wake_executor) come to wake() below, so that a
        # subscription created later is wrapped too (the Node.executor setter would remove the
        # node from rclpy's executor first)
        node._Node__executor_weakref = weakref.ref(self)
        return added

    def remove_node(self, node) -> None:
        self._ex.remove_node(node)

    def get_nodes(self):
        return self._ex.get_nodes()

    def wake(self) -> None:
        for node in self._ex.get_nodes():
            self._unpack_message_info(node)
        self._ex.wake()

    def spin_once(self, timeout_sec: float | None = None) -> None:
        self._ex.spin_once(timeout_sec=self.POLL if timeout_sec is None or timeout_sec < 0 else timeout_sec)

    def spin(self) -> None:
        while self._context.ok() and not self._stop:
            self._ex.spin_once(timeout_sec=self.POLL)

    def shutdown(self, timeout_sec: float | None = None) -> bool:
        self._stop = True
        return self._ex.shutdown(timeout_sec) if timeout_sec is not None else self._ex.shutdown()
