"""The range policy (switchobs_core.ranges): every number a user gives has a documented
range; sizes that grow with a user's numbers are refused up front, with the amount."""

from __future__ import annotations

import math
import time
import tracemalloc

import pytest

from switchobs_core import ranges
from switchobs_core.design.kalman import design_bytes, design_kalman, design_pattern, sample_pattern, startup_cap
from switchobs_core.design.plan import plan_schedule
from switchobs_core.exceptions import InvalidArgument
from switchobs_core.model.scenarios import camera_agents, paper_system
from switchobs_core.model.schedule import Cycle
from switchobs_core.table.gains import kalman_table


@pytest.mark.parametrize("name, value", [
    ("sensor_timeout", 1.0e10), ("future_tolerance", 1.0e300), ("diagnostics_period", 1.0e12),
    ("pairing_timeout", 0.0), ("e0", 1.0e308), ("e0", -1.0), ("initial_estimate", 1.0e300),
    ("noise.max", 1.0e150), ("rate", 1.0e9), ("rate", math.nan), ("sensor_timeout", math.inf),
])
def test_out_of_range_is_refused_with_the_range_and_why(name, value):
    with pytest.raises(InvalidArgument) as info:
        ranges.check_range(value, name)
    msg = str(info.value)
    assert f"'{name}'" in msg and "must be in" in msg and "\n" not in msg, msg


@pytest.mark.parametrize("name, value", [
    ("sensor_timeout", 0.5), ("sensor_timeout", ranges.MAX_DURATION_S), ("e0", 0.0), ("e0", 1.0e50),
    ("initial_estimate", -1.0e50), ("noise.max", -1.0), ("rate", 0.0), ("rate", 1.0e6),
])
def test_in_range_is_accepted(name, value):
    assert ranges.check_range(value, name) == value


def test_durations_fit_an_int64_of_nanoseconds_after_any_stamp_before_2262():
    assert ranges.MAX_DURATION_S * 1e9 + 4e18 < 2**63


def test_check_size_names_the_amount_and_the_budget():
    with pytest.raises(InvalidArgument, match=r"2e\+09 samples would need 14.9 GiB, beyond the budget of 1 GiB: "
                                              r"lower it"):
        ranges.check_size(2e9, 8, "2e+09 samples", "lower it")
    assert ranges.check_size(1000, 8, "x", "y") == 1000
    with pytest.raises(InvalidArgument, match="unbounded"):
        ranges.check_size(math.inf, 8, "x", "y")


def test_check_count():
    with pytest.raises(InvalidArgument, match="cycles: 30000 given, at most 1000"):
        ranges.check_count(30000, "cycles", ranges.MAX_CYCLES)


def test_kalman_design_at_1e9_hz_is_refused_at_once():
    """`design --gains kalman --rate 1e9` tried to allocate 15 GiB (MemoryError traceback)."""
    t0 = time.monotonic()
    with pytest.raises(InvalidArgument, match=r"samples per period .* would need .*TiB, beyond the budget"):
        design_kalman(paper_system(), [Cycle.from_ts(2.0, 0.6)], 1e9)
    with pytest.raises(InvalidArgument, match="beyond the budget"):
        sample_pattern([Cycle.from_ts(2.0, 0.6)], 1e9)
    assert time.monotonic() - t0 < 5


def test_kalman_design_of_32_agents_passes_the_budget_and_ten_times_its_rate_does_not():
    """`design camera_agents(32) --gains kalman --rate 50` was refused ('1.6e+03 samples per period
    (32 s at 50 Hz) would need 1.05 GiB') though it runs in 0.95 GiB peak RSS: the estimate counted
    five n x n matrices per sample. The check alone (no design): it passes at 50 Hz, and at 500 Hz
    (ten times the samples, no start-up cap left to absorb them) it is refused with one line."""
    system = camera_agents(32)
    cycle = Cycle([1.0] * 32)
    pattern = design_pattern(system, cycle, 50.0)
    assert pattern.K == 1600 and startup_cap(1600, system.n) == 1925
    need = design_bytes(system.n, max(system.p), 1600, 1925)
    assert 0.5 * ranges.MEMORY_BUDGET_BYTES < need < ranges.MEMORY_BUDGET_BYTES
    with pytest.raises(InvalidArgument) as info:
        design_kalman(system, cycle, 500.0)
    msg = str(info.value)
    assert msg.startswith("1.6e+04 samples per period (32 s at 500 Hz) would need 6.68 GiB, beyond the budget "
                          "of 1 GiB: lower the rate") and "\n" not in msg, msg


@pytest.mark.parametrize("agents, startup", [(2, 0), (2, 150), (4, 200)])
def test_design_bytes_bounds_what_a_kalman_design_and_its_table_allocate(tmp_path, agents, startup):
    """The budget's estimate (design_bytes) against the allocations tracemalloc sees for the design and
    the binary table written from it (a start-up that never meets the periodic solution,
    startup_rtol = 0, stores exactly ``startup`` samples): at least all of them, measured first
    (cold or not: that depends on what ran before in this process; a cold design also allocates
    scipy's lazy imports and caches, 20-30 kB), and at most 30 % more than a warm design's (the
    smallest case, n = 12 without a start-up, 26 %; the others 8-17 %)."""
    system = camera_agents(agents)
    est = None
    peaks = []
    for i in range(2):
        tracemalloc.start()
        try:
            kd = design_kalman(system, Cycle([1.0] * agents), 50.0, max_startup=startup, startup_rtol=0.0)
            kalman_table(system, [kd]).save(tmp_path / f"k{i}.npz")
            peaks.append(tracemalloc.get_traced_memory()[1])
        finally:
            tracemalloc.stop()
        assert len(kd.startup) == startup
        est = design_bytes(system.n, max(system.p), kd.pattern.K, startup)
    assert peaks[0] <= est and peaks[1] <= est <= 1.3 * peaks[1], (peaks, est)


@pytest.mark.parametrize("rate, tau_max", [(1e9, 4.0), (50.0, 1e9)])
def test_plan_sizes_are_refused_at_once(rate, tau_max):
    t0 = time.monotonic()
    with pytest.raises(InvalidArgument, match=r"periods of up to .* samples .* beyond the budget"):
        plan_schedule(paper_system(), rate, tau_max=tau_max, progress=False)
    assert time.monotonic() - t0 < 5


def test_fmt_bytes():
    assert ranges.fmt_bytes(512) == "512 bytes"
    assert ranges.fmt_bytes(3 << 30) == "3 GiB"
