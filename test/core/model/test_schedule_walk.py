"""The schedules' walk over their cycles (``Schedule._locate``): one schedule asked at times in any
order answers exactly as a fresh one asked once (which walks from t0), ties and dead times included."""

from __future__ import annotations

from hypothesis import given, settings
from hypothesis import strategies as st

from switchobs_core.model.schedule import Cycle, RandomSchedule, SequenceSchedule

_h = st.floats(0.05, 5.0, allow_nan=False, allow_infinity=False)


def _answers(sch, t):
    return sch.channel_at(t), sch.slot_at(t), sch.blind_at(t)


@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(_h, _h), min_size=1, max_size=5), st.floats(0.0, 0.04), st.floats(-3.0, 3.0),
       st.lists(st.floats(-5.0, 400.0, allow_nan=False), min_size=1, max_size=40), st.data())
def test_sequence_walk_in_any_order_equals_a_fresh_walk(hs, dead, t0, times, data):
    cycles = [Cycle(h, dead) for h in hs]
    # some queries exactly at switching instants (the tie rule) and just before them
    inst = SequenceSchedule(cycles, t0).switching_instants(t0 + 400.0)
    picks = data.draw(st.lists(st.sampled_from(list(inst)), max_size=10))
    times = times + picks + [p - 1e-10 for p in picks]
    times = data.draw(st.permutations(times))
    kept = SequenceSchedule(cycles, t0)
    for t in times:
        assert _answers(kept, t) == _answers(SequenceSchedule(cycles, t0), t), t


@settings(max_examples=20, deadline=None)
@given(st.integers(0, 2**16), st.lists(st.floats(-1.0, 300.0, allow_nan=False), min_size=1, max_size=30))
def test_random_schedule_walk_in_any_order_equals_a_fresh_walk(seed, times):
    kept = RandomSchedule(3, 0.3, 2.0, seed=seed)
    for t in times:
        assert _answers(kept, t) == _answers(RandomSchedule(3, 0.3, 2.0, seed=seed), t), t
