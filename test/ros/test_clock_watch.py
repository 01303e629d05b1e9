"""The clock watch (switchobs_ros.clocks): a negative latency beyond the declared tolerance proves a
sender's clock ahead; with a tolerance of 0 (one computer declared) the middleware's system-clock
timestamps are still checked, the header stamps are not."""

from __future__ import annotations

from switchobs_ros.clocks import SYSTEM_MARGIN_NS, ClockWatch

MS = 1_000_000


def test_a_declared_tolerance_is_checked_on_header_stamps():
    w = ClockWatch(3 * MS)
    assert w.seen("target/pose", 1_000 * MS, 998 * MS) == ""            # 2 ms ahead: within
    why = w.seen("target/pose", 1_050 * MS, 1_000 * MS)                 # 50 ms ahead
    assert "target/pose" in why and "50.000 ms ahead" in why and "clock_tolerance_ms = 3" in why
    assert w.seen("target/pose", 1_060 * MS, 1_000 * MS) == ""          # said once per source
    assert w.skewed == {"target/pose": 60 * MS} and w.offsets_ms()["target/pose"] == -60.0


def test_zero_tolerance_checks_only_system_clock_timestamps():
    w = ClockWatch(0)
    assert w.seen("target/pose", 1_050 * MS, 1_000 * MS) == ""          # header stamps: sim time, tests
    assert w.seen("dds", 1_000 * MS + SYSTEM_MARGIN_NS, 1_000 * MS, system=True) == ""
    why = w.seen("dds", 1_050 * MS, 1_000 * MS, system=True)            # another computer 50 ms ahead
    assert "dds" in why and "50.000 ms ahead" in why and "one computer declared" in why
    assert w.seen("dds2", 1_000 * MS, 1_002 * MS, system=True) == ""    # a positive latency never
