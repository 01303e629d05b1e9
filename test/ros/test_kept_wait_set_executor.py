"""switchobs_ros.executor.KeptWaitSetExecutor: every entity served, in order, one wait per wake-up."""

from __future__ import annotations

import contextlib
import threading
import time

import pytest
import rclpy
from rclpy.executors import ExternalShutdownException
from rclpy.qos import QoSProfile, ReliabilityPolicy
from std_msgs.msg import Int32, String
from std_srvs.srv import Trigger

from switchobs_ros.executor import KeptWaitSetExecutor, PolledEventsExecutor

RELIABLE = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)


@pytest.fixture
def ctx():
    context = rclpy.Context()
    rclpy.init(context=context)
    yield context
    rclpy.try_shutdown(context=context)


def spin_until(ex: KeptWaitSetExecutor, done, limit: float = 20.0) -> None:
    """Spin until ``done()`` (the limit only ends a broken run; nothing here is timed)."""
    end = time.monotonic() + limit
    while not done() and time.monotonic() < end:
        ex.spin_once(timeout_sec=0.1)
    assert done()


def wait_matched(ex, pub, limit: float = 20.0) -> None:
    spin_until(ex, lambda: pub.get_subscription_count() > 0, limit)


@contextlib.contextmanager
def _spun(ctx, *names: str, executor=KeptWaitSetExecutor):
    """An executor of ``executor``'s class with a node of each name added: ``(ex, *nodes)``; the
    nodes destroyed and the executor shut down on the way out, also when the test fails."""
    ex = executor(context=ctx)
    nodes = [rclpy.create_node(name, context=ctx) for name in names]
    try:
        for node in nodes:
            ex.add_node(node)
        yield (ex, *nodes)
    finally:
        for node in nodes:
            node.destroy_node()
        ex.shutdown()


def test_timers_fire_and_a_cancelled_timer_does_not(ctx):
    with _spun(ctx, "kws_timers") as (ex, node):
        fired, cancelled = [], []
        node.create_timer(0.01, lambda: fired.append(1))
        dead = node.create_timer(0.005, lambda: cancelled.append(1))
        dead.cancel()
        spin_until(ex, lambda: len(fired) >= 5)
        assert cancelled == []
        dead.reset()        # re-armed: it fires again
        spin_until(ex, lambda: len(cancelled) >= 1)


def test_messages_taken_in_order_one_wait_each_and_the_wait_set_kept(ctx):
    with _spun(ctx, "kws_sub") as (ex, node):
        got, infos = [], []

        def with_info(msg, info):
            got.append(msg.data)
            infos.append(info)
        node.create_subscription(Int32, "/kws_in", with_info, RELIABLE)
        pub = node.create_publisher(Int32, "/kws_in", RELIABLE)
        wait_matched(ex, pub)
        for i in range(40):
            pub.publish(Int32(data=i))
        spin_until(ex, lambda: len(got) >= 1)
        rebuilds = ex.rebuilds
        calls, waits = ex.calls, ex.waits
        spin_until(ex, lambda: len(got) == 40)
        assert got == list(range(40))
        assert all(info.get("source_timestamp") for info in infos)        # MessageInfo passed
        assert ex.rebuilds == rebuilds           # the wait set was not rebuilt for any of them
        # one wait per callback at most (rclpy's executor: two, one of them woken by its own guard)
        assert ex.waits - waits <= ex.calls - calls
        # a subscription created later is served after the executor rebuilds its wait set
        late = []
        node.create_subscription(Int32, "/kws_late", lambda m: late.append(m.data), RELIABLE)
        pub2 = node.create_publisher(Int32, "/kws_late", RELIABLE)
        wait_matched(ex, pub2)
        pub2.publish(Int32(data=7))
        spin_until(ex, lambda: late == [7])
        assert ex.rebuilds > rebuilds


def test_entities_ready_in_one_wait_served_in_creation_order(ctx):
    """Three subscriptions ready together are called in the order they were created (rclpy's), not
    the order their messages were published in."""
    with _spun(ctx, "kws_order") as (ex, node):
        got = []
        for name in ("c", "a", "b"):
            node.create_subscription(Int32, f"/kws_order_{name}", lambda m, name=name: got.append(name), RELIABLE)
        pubs = {name: node.create_publisher(Int32, f"/kws_order_{name}", RELIABLE) for name in ("a", "b", "c")}
        for pub in pubs.values():
            wait_matched(ex, pub)
        for _ in range(3):          # the wake-ups of the entities' creation, consumed
            ex.spin_once(timeout_sec=0.05)
        for name in ("a", "b", "c"):
            pubs[name].publish(Int32(data=1))
        time.sleep(0.2)             # all three delivered before the wait (nothing is timed)
        waits = ex.waits
        spin_until(ex, lambda: len(got) == 3)
        assert got == ["c", "a", "b"]
        assert ex.waits - waits == 1


def test_entries_discarded_after_a_callback_took_their_messages(ctx):
    """A callback that takes another ready subscription's message itself and discards its queued
    entry: that subscription's callback is not called for it (its message was handled once, by the
    taker), and a later message of it is served as usual (nothing lost)."""
    with _spun(ctx, "kws_discard") as (ex, node):
        got = []

        def first(m):
            got.append(("first", m.data))
            with second.handle:
                taken = second.handle.take_message(second.msg_type, second.raw)
            if taken is not None:
                got.append(("taken", taken[0].data))
            ex.discard_ready((second,))

        node.create_subscription(Int32, "/kws_discard_a", first, RELIABLE)
        second = node.create_subscription(Int32, "/kws_discard_b", lambda m: got.append(("second", m.data)),
                                          RELIABLE)
        pubs = [node.create_publisher(Int32, f"/kws_discard_{name}", RELIABLE) for name in ("a", "b")]
        for pub in pubs:
            wait_matched(ex, pub)
        for _ in range(3):          # the wake-ups of the entities' creation, consumed
            ex.spin_once(timeout_sec=0.05)
        pubs[0].publish(Int32(data=1))
        pubs[1].publish(Int32(data=2))
        time.sleep(0.2)             # both delivered before the wait (nothing is timed)
        waits = ex.waits
        spin_until(ex, lambda: ("taken", 2) in got)
        assert ex.waits - waits == 1 and not ex._ready
        pubs[1].publish(Int32(data=3))
        spin_until(ex, lambda: ("second", 3) in got)
        assert got == [("first", 1), ("taken", 2), ("second", 3)]


def test_a_discarded_entry_with_messages_left_is_served_without_a_new_message(ctx):
    """A callback takes one of two waiting messages of another subscription and discards its queued
    entry: the next wait reports the subscription again (rcl's wait is level-triggered), so the second
    message is served without a new one arriving."""
    with _spun(ctx, "kws_level") as (ex, node):
        got = []

        def first(m):
            got.append(("first", m.data))
            with second.handle:
                taken = second.handle.take_message(second.msg_type, second.raw)   # one of two
            got.append(("taken", taken[0].data))
            ex.discard_ready((second,))

        node.create_subscription(Int32, "/kws_level_a", first, RELIABLE)
        second = node.create_subscription(Int32, "/kws_level_b", lambda m: got.append(("second", m.data)), RELIABLE)
        pubs = [node.create_publisher(Int32, f"/kws_level_{n}", RELIABLE) for n in ("a", "b")]
        for pub in pubs:
            wait_matched(ex, pub)
        for _ in range(3):
            ex.spin_once(timeout_sec=0.05)
        pubs[0].publish(Int32(data=1))
        pubs[1].publish(Int32(data=2))
        pubs[1].publish(Int32(data=3))
        time.sleep(0.2)
        spin_until(ex, lambda: ("second", 3) in got, limit=5.0)
        assert got == [("first", 1), ("taken", 2), ("second", 3)]


def test_middleware_events_of_publishers_and_subscriptions_are_served(ctx):
    """The QoS events rclpy attaches to publishers and subscriptions (waitables the kept wait set
    adds without their Python wrappers): an incompatible reliability is reported to both sides'
    callbacks, and the messages of a compatible pair still arrive."""
    from rclpy.event_handler import PublisherEventCallbacks, SubscriptionEventCallbacks
    with _spun(ctx, "kws_qos") as (ex, node):
        requested, offered, got = [], [], []
        node.create_subscription(Int32, "/kws_qos", got.append, RELIABLE,
                                 event_callbacks=SubscriptionEventCallbacks(
                                     incompatible_qos=lambda e: requested.append(e.total_count)))
        best_effort = QoSProfile(depth=10, reliability=ReliabilityPolicy.BEST_EFFORT)
        node.create_publisher(Int32, "/kws_qos", best_effort, event_callbacks=PublisherEventCallbacks(
            incompatible_qos=lambda e: offered.append(e.total_count)))
        spin_until(ex, lambda: requested and offered)
        assert requested[-1] >= 1 and offered[-1] >= 1
        pub = node.create_publisher(Int32, "/kws_qos", RELIABLE)
        wait_matched(ex, pub)
        pub.publish(Int32(data=5))
        spin_until(ex, lambda: [m.data for m in got] == [5])


def test_raw_subscription_gets_bytes(ctx):
    with _spun(ctx, "kws_raw") as (ex, node):
        got = []
        node.create_subscription(Int32, "/kws_raw", got.append, RELIABLE, raw=True)
        pub = node.create_publisher(Int32, "/kws_raw", RELIABLE)
        wait_matched(ex, pub)
        pub.publish(Int32(data=0x01020304))
        spin_until(ex, lambda: len(got) == 1)
        assert isinstance(got[0], bytes) and got[0][-4:] == bytes([4, 3, 2, 1])    # CDR little endian


def test_services_answer_clients_and_parameter_services(ctx):
    with _spun(ctx, "kws_server", "kws_client") as (ex, server, client_node):
        calls = []

        def answer(req, resp):
            calls.append(1)
            resp.success, resp.message = True, f"call {len(calls)}"
            return resp
        server.create_service(Trigger, "/kws_trigger", answer)
        cli = client_node.create_client(Trigger, "/kws_trigger")
        spin_until(ex, cli.service_is_ready)
        for k in (1, 2):
            fut = cli.call_async(Trigger.Request())
            ex.spin_until_future_complete(fut, timeout_sec=20.0)
            assert fut.done() and fut.result().success and fut.result().message == f"call {k}"
        # the node's own parameter services
        server.declare_parameter("gain", 1.5)
        from rcl_interfaces.srv import GetParameters
        pcli = client_node.create_client(GetParameters, "/kws_server/get_parameters")
        spin_until(ex, pcli.service_is_ready)
        fut = pcli.call_async(GetParameters.Request(names=["gain"]))
        ex.spin_until_future_complete(fut, timeout_sec=20.0)
        assert fut.result().values[0].double_value == 1.5


def test_guard_conditions_and_coroutine_callbacks(ctx):
    with _spun(ctx, "kws_guard") as (ex, node):
        hits, steps = [], []
        gc = node.create_guard_condition(lambda: hits.append(1))
        gc.trigger()
        spin_until(ex, lambda: hits == [1])

        async def coro():
            steps.append("a")
        node.create_timer(0.01, coro)
        spin_until(ex, lambda: len(steps) >= 2)


def test_shutdown_ends_spin_from_another_thread_and_from_the_context(ctx):
    node = rclpy.create_node("kws_stop", context=ctx)
    ex = KeptWaitSetExecutor(context=ctx)
    ex.add_node(node)
    out = []

    def run():
        try:
            ex.spin()
            out.append("returned")
        except ExternalShutdownException:
            out.append("external")
    t = threading.Thread(target=run)
    t.start()
    time.sleep(0.2)
    ex.shutdown()
    t.join(20.0)
    assert not t.is_alive() and out == ["returned"]
    node.destroy_node()

    # the context shut down (as Ctrl-C does) while spinning with nothing to do
    node2 = rclpy.create_node("kws_stop2", context=ctx)
    ex2 = KeptWaitSetExecutor(context=ctx)
    ex2.add_node(node2)
    def run2():
        try:
            ex2.spin()
            out.append("returned2")
        except ExternalShutdownException:
            out.append("external2")
    t2 = threading.Thread(target=run2)
    t2.start()
    time.sleep(0.2)
    rclpy.shutdown(context=ctx)
    t2.join(20.0)
    assert not t2.is_alive() and out[-1] in ("returned2", "external2")


def test_spin_keeps_handles_entered_and_a_callback_destroys_and_recreates_a_subscription(ctx):
    """Inside ``spin`` the handles stay entered between waits; a subscription a callback destroys is
    destroyed at once (its rcl pointer 0), so that the callback can subscribe to its topic with
    another type (the estimator's channel subscription); the new one is served, and every handle is
    released when ``spin`` returns."""
    node = rclpy.create_node("kws_hold", context=ctx)
    ex = KeptWaitSetExecutor(context=ctx)
    ex.add_node(node)
    got, late, seen, subs = [], [], {}, []
    pub = node.create_publisher(Int32, "/kws_trigger", RELIABLE)

    def first(msg):
        got.append(msg.data)
        if len(got) == 1:
            seen["in_spin"] = ex._entered is not None       # the handles held across waits
            node.destroy_subscription(subs[0])
            seen["after_destroy"] = subs[0].handle.pointer
            subs.append(node.create_subscription(String, "/kws_hold", lambda m: late.append(m.data), RELIABLE))

    subs.append(node.create_subscription(Int32, "/kws_hold", lambda m: None, RELIABLE))
    node.create_subscription(Int32, "/kws_trigger", first, RELIABLE)
    pub_late = [None]

    def tick():
        if not got and pub.get_subscription_count():
            pub.publish(Int32(data=1))
        elif len(subs) == 2 and pub_late[0] is None:
            pub_late[0] = node.create_publisher(String, "/kws_hold", RELIABLE)
        elif pub_late[0] is not None and pub_late[0].get_subscription_count() and not late:
            pub_late[0].publish(String(data="two"))
        elif late:
            ex.shutdown()
    node.create_timer(0.01, tick)
    t = threading.Thread(target=ex.spin)
    t.start()
    t.join(20.0)
    if t.is_alive():
        ex.shutdown()
        t.join(5.0)
    try:
        assert got == [1] and late == ["two"]
        assert seen["in_spin"] and seen["after_destroy"] == 0
        assert ex._entered is None          # spin returned: nothing held
        handle = subs[1].handle
        node.destroy_node()
        assert handle.pointer == 0          # nothing kept the node's entities alive
    finally:
        ex.shutdown()


def test_polled_events_executor_delivers_messages_with_their_info_and_fires_timers(ctx):
    with _spun(ctx, "kws_events", executor=PolledEventsExecutor) as (ex, node):
        got, ticks = [], []
        node.create_subscription(Int32, "/kws_ev", lambda m, info: got.append((m.data, info["source_timestamp"])),
                                 RELIABLE)
        pub = node.create_publisher(Int32, "/kws_ev", RELIABLE)
        node.create_timer(0.01, lambda: ticks.append(1))
        wait_matched(ex, pub)
        for i in range(10):
            pub.publish(Int32(data=i))
        spin_until(ex, lambda: len(got) == 10 and len(ticks) >= 3)
        assert [d for d, _ in got] == list(range(10)) and all(ts > 0 for _, ts in got)


def test_a_subscription_another_thread_destroys_during_a_callback_is_destroyed_at_once(ctx):
    """While the spinner runs a callback, another thread destroys a subscription: it is destroyed
    at once (rcl pointer 0), as with rclpy's executor, and that thread can subscribe to the topic
    with another type; spinning goes on and serves the new subscription."""
    with _spun(ctx, "kws_thread") as (ex, node):
        busy, go, late = threading.Event(), threading.Event(), []
        sub = node.create_subscription(Int32, "/kws_thread", lambda m: None, RELIABLE)

        def slow():
            busy.set()
            go.wait(20.0)
        timer = node.create_timer(0.01, slow)
        t = threading.Thread(target=ex.spin)
        t.start()
        try:
            assert busy.wait(20.0)
            node.destroy_subscription(sub)
            pointer = sub.handle.pointer
            node.create_subscription(String, "/kws_thread", lambda m: late.append(m.data), RELIABLE)
            node.destroy_timer(timer)
        finally:
            go.set()
        pub = node.create_publisher(String, "/kws_thread", RELIABLE)
        end = time.monotonic() + 20.0       # ends a broken run only
        while not late and time.monotonic() < end:
            if pub.get_subscription_count():
                pub.publish(String(data="x"))
            time.sleep(0.01)
        ex.shutdown()
        t.join(20.0)
        assert pointer == 0 and late and late[0] == "x"
        assert ex._entered is None


def test_a_subscription_another_thread_destroys_during_a_wait_is_destroyed_when_it_returns(ctx):
    """Destroyed by another thread while the spinner waits, a subscription is destroyed once that
    wait returns (the wake-up ends it), without a callback or a further wait."""
    with _spun(ctx, "kws_thread_wait") as (ex, node):
        sub = node.create_subscription(Int32, "/kws_thread_wait", lambda m: None, RELIABLE)
        t = threading.Thread(target=ex.spin)
        t.start()
        try:
            end = time.monotonic() + 20.0    # ends a broken run only
            while not (ex._in_wait and ex._entered is not None) and time.monotonic() < end:
                time.sleep(0.005)
            node.destroy_subscription(sub)
            while sub.handle.pointer != 0 and time.monotonic() < end:
                time.sleep(0.005)
            assert sub.handle.pointer == 0
        finally:
            ex.shutdown()
            t.join(20.0)


def test_entering_interrupted_exits_the_handles_it_entered(ctx):
    """An exception other than InvalidHandle while the handles are entered (a KeyboardInterrupt
    between two enters) leaves none of them entered: a subscription destroyed afterwards is
    destroyed at once."""
    from switchobs_ros.executor import _Plan

    class Interrupting:
        def __enter__(self):
            raise KeyboardInterrupt

    with _spun(ctx, "kws_interrupt") as (ex, node):
        sub = node.create_subscription(Int32, "/kws_interrupt", lambda m: None, RELIABLE)
        plan = _Plan(ex)
        plan.adds.append((None, Interrupting()))
        with pytest.raises(KeyboardInterrupt):
            plan.enter()
        node.destroy_subscription(sub)
        assert sub.handle.pointer == 0
        assert plan.entered == [] and plan.live == []


def test_release_interrupted_still_exits_every_handle(ctx):
    """A KeyboardInterrupt between the exits of :meth:`_Plan.release` (here raised by one handle's exit,
    after it exited) propagates, and every other handle entered is exited all the same: a subscription
    destroyed afterwards is destroyed at once, and nothing stays held."""
    from switchobs_ros.executor import _Plan

    class InterruptedAfterExit:
        exits = 0

        def __enter__(self):
            return self

        def __exit__(self, *exc):
            self.exits += 1
            raise KeyboardInterrupt

    with _spun(ctx, "kws_release") as (ex, node):
        sub = node.create_subscription(Int32, "/kws_release", lambda m: None, RELIABLE)
        plan = _Plan(ex)
        first, last = InterruptedAfterExit(), InterruptedAfterExit()
        plan.adds.append((None, first))         # both exited before the subscription: an interrupt,
        plan.adds.append((None, last))          # then a second one while the rest is exited
        plan.enter()
        held = len(plan.entered)
        assert held >= 3 and plan.entered.index(sub.handle) < plan.entered.index(first)
        node.destroy_subscription(sub)
        assert sub.handle.pointer != 0          # entered: its destruction waits for the release
        with pytest.raises(KeyboardInterrupt) as raised:
            plan.release()
        assert isinstance(raised.value.__context__, KeyboardInterrupt)     # the second, during the first
        assert sub.handle.pointer == 0          # exited despite the interrupts, destroyed then
        assert first.exits == 1 and last.exits == 1
        assert plan.entered == [] and plan.live == [] and plan.live_waitables == []


def test_an_entity_another_thread_creates_during_a_rebuild_is_served(ctx, monkeypatch):
    """Another thread creates a timer while the spinner builds its wait set, after the build read the
    node's entities: the change is not lost under the plan being built (the next wait rebuilds), and
    the timer fires."""
    import switchobs_ros.executor as executor_module
    with _spun(ctx, "kws_rebuild") as (ex, node):
        fired, armed = [], threading.Event()
        build = executor_module._Plan.__init__

        def build_while_another_thread_creates(self, executor):
            build(self, executor)
            if armed.is_set():
                armed.clear()
                count = len(list(node.timers))
                threading.Thread(target=lambda: node.create_timer(0.01, lambda: fired.append(1))).start()
                end = time.monotonic() + 20.0       # ends a broken run only
                while len(list(node.timers)) == count and time.monotonic() < end:
                    time.sleep(0.001)
                time.sleep(0.05)                    # the other thread on to its wake()

        monkeypatch.setattr(executor_module._Plan, "__init__", build_while_another_thread_creates)
        t = threading.Thread(target=ex.spin)
        t.start()
        try:
            armed.set()
            ex.wake()
            end = time.monotonic() + 20.0
            while not fired and time.monotonic() < end:
                time.sleep(0.01)
        finally:
            ex.shutdown()
            t.join(20.0)
        assert fired
