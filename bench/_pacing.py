"""Shared by the benchmark drivers: wait for a send time without burning a core."""

from __future__ import annotations

import time


def sleep_until(t_next: float) -> None:
    """Return at ``time.perf_counter() >= t_next``: sleep while more than 1.5 ms remain, then spin."""
    while True:
        d = t_next - time.perf_counter()
        if d <= 0:
            return
        if d > 0.0015:
            time.sleep(d - 0.001)
