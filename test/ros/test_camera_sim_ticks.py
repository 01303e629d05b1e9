"""camera_sim's ticks on its timer's grid: a timer call late by less than a period publishes the
next tick whatever the lateness of the first call was; a call more than a period late skips the
ticks it missed; no stamp is later than the call that publishes it."""

from __future__ import annotations

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

PERIOD_NS = 20_000_000      # 50 Hz
T0_NS = 5_000_000_000_000   # the timer's first due time on the node clock


class _Clock:
    """The node clock at the scripted time of the call being run."""

    def __init__(self) -> None:
        self.ns = 0

    def now(self):
        from rclpy.time import Time
        return Time(nanoseconds=self.ns)


class _Timer:
    """rcl's timer seen from its callback: the next call is due one period after this one's due time
    (after the due times a late call missed)."""

    def __init__(self, clock: _Clock) -> None:
        self.clock, self.due = clock, T0_NS

    def time_until_next_call(self) -> int:
        return self.due + PERIOD_NS - self.clock.ns

    def cancel(self) -> None:
        pass


def _run(lateness_ns: list[int]) -> tuple[list[int], list[int]]:
    """Call camera_sim's tick callback at due time ``j`` plus ``lateness_ns[j]`` (a call later than a
    period takes the due time of its period, as rcl's timer does): (the ticks published, their stamps
    less the time of the call that published them)."""
    from rclpy.parameter import Parameter

    from switchobs_ros.camera_sim import CameraSimNode

    node = CameraSimNode(parameter_overrides=[Parameter("rate", value=50.0)])
    try:
        node.timer.cancel()
        clock, sent = _Clock(), []
        timer = _Timer(clock)
        node.timer, node.get_clock = timer, (lambda: clock)
        node.publish_tick = lambda k: sent.append((k, node.epoch_ns + k * PERIOD_NS, clock.ns))
        due = T0_NS
        for late in lateness_ns:
            clock.ns = due + late
            timer.due = due + (late // PERIOD_NS) * PERIOD_NS     # the due time rcl advanced past
            node.tick_callback()
            due = timer.due + PERIOD_NS
        return [k for k, _, _ in sent], [s - now for _, s, now in sent]
    finally:
        node.destroy_node()


def test_a_first_call_later_than_the_rest_skips_no_tick(ros_node):
    """The first call 9 ms late, the others 1 ms: every tick published once (an epoch at the first
    call's time would put every later call before its tick's stamp and drop every other tick)."""
    ticks, ahead = _run([9_000_000] + [1_000_000] * 99)
    assert ticks == list(range(100))
    assert max(ahead) <= 0


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.lists(st.integers(0, PERIOD_NS - 1), min_size=2, max_size=60))
def test_calls_late_by_less_than_a_period_publish_every_tick(ros_node, lateness):
    ticks, ahead = _run(lateness)
    assert ticks == list(range(len(lateness)))
    assert max(ahead) <= 0      # a stamp is never later than the call that publishes it


@pytest.mark.parametrize("periods", [1, 3])
def test_a_call_more_than_a_period_late_skips_the_ticks_it_missed(ros_node, periods):
    late = [2_000_000] * 10
    late[5] = periods * PERIOD_NS + 4_000_000
    ticks, ahead = _run(late)
    assert ticks == [*range(5), *range(5 + periods, 10 + periods)]
    assert max(ahead) <= 0
