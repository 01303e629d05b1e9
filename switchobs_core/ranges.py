"""The range of every number a user gives, derived from what the code does with it.

One owner for the limits that the start-up checks, the params files, the runtime
``set_parameters`` callback and the command-line tools apply. Each limit says why it is what
it is:

* **Durations** (:data:`MAX_DURATION_S`, 1e6 s, about 11.6 days): a timeout or a period becomes
  an integer number of nanoseconds (an int64 in rclpy's ``Duration`` and timers, and in the
  stamp arithmetic ``stamp + timeout``). 1e6 s is 1e15 ns: any stamp before the year 2262
  plus such a duration still fits an int64, and no timeout of a sensor pipeline needs more.
  A float such as 1e10 s (1e19 ns) overflows the int64 and raised ``OverflowError`` at start-up.
  A node's own timer period is at least :data:`MIN_TIMER_PERIOD_S` (10 ms).
* **Magnitudes** of what enters the observer's state (:data:`MAX_MAGNITUDE`, 1e50): the
  initial estimate, the initial error bound ``e0``, the declared noise bound ``noise.max``, noise
  standard deviations and the largest accepted sample (``max_abs_value``).
  The exact bound and the rounding bound keep *squared* sizes (ellipsoid shape matrices hold
  ``e0^2``, ``|v|^2`` and ``|x_hat|^2 eps^2``) and multiply them by the step's squared error
  map; 1e50 squared is 1e100, leaving 1e200 for those factors before a double overflows.
  Measured on the paper's model: 1e75 still answered every sample, 1e100 made the first exact
  step overflow (every second measurement went unanswered, with exit 0), for an initial estimate
  and for samples alike (the observer itself refuses samples above 1e150 only).
* **Rates** (:data:`MAX_RATE_HZ`, 1e6 Hz): one sample per microsecond; a node handles a few
  thousand messages per second. Above the rate, the *sizes* below decide.
* **Sizes** (:func:`check_size`): whatever grows with a number the user gives (samples per
  period = rate x period, messages = rate x duration, cycles in a schedule) is computed up
  front and refused with the amount when it exceeds :data:`MEMORY_BUDGET_BYTES` (1 GiB, a
  quarter of the 4 GB address space a tool gets, the rest being Python, numpy, rclpy) or, for
  files written, :data:`OUTPUT_BUDGET_BYTES`.
* **Counts** (:data:`MAX_CYCLES`, 1000): cycles of a schedule (the observer and the design
  handle them in loops over pairs); a real sequence has a handful.

Every refusal is an :class:`~switchobs_core.exceptions.InvalidArgument` (or the caller's error
class) with one line naming the value, its range and why.
"""

from __future__ import annotations

import math
from typing import Any

from .exceptions import InvalidArgument, SwitchobsError

__all__ = [
    "MAX_DURATION_S",
    "MIN_TIMER_PERIOD_S",
    "MAX_MAGNITUDE",
    "MAX_RATE_HZ",
    "MAX_CYCLES",
    "MAX_STAMP_S",
    "MEMORY_BUDGET_BYTES",
    "OUTPUT_BUDGET_BYTES",
    "RANGES",
    "check_range",
    "check_seconds",
    "check_size",
    "check_count",
    "fmt_bytes",
]

#: Longest duration (s) a user gives: timeouts, periods (module docstring).
MAX_DURATION_S = 1.0e6
#: Shortest period of a node's own timer (s): building and publishing /diagnostics takes about a
#: millisecond; a shorter period would take the CPU that the measurements need.
MIN_TIMER_PERIOD_S = 0.01
#: Largest magnitude of the initial estimate, ``e0`` and ``noise.max`` (module docstring).
MAX_MAGNITUDE = 1.0e50
#: Highest sample rate (Hz).
MAX_RATE_HZ = 1.0e6
#: Latest stamp (s) a message carries: ``builtin_interfaces/Time.sec`` is an int32.
MAX_STAMP_S = 2**31 - 1
#: Most cycles in a schedule (``schedule.h`` / ``schedule.tau``, ``--cycle``).
MAX_CYCLES = 1000
#: Memory a computation sized by the user's numbers may take (bytes).
MEMORY_BUDGET_BYTES = 1 << 30
#: Size of a file a tool writes from the user's numbers (bytes): a generated bag. The bag
#: readers refuse larger data files (:data:`switchobs_core.files.MAX_BAG_BYTES` is this).
OUTPUT_BUDGET_BYTES = 1 << 30

#: The documented ranges, by the name a user gives (params file, ``-p``, CLI flag):
#: ``(low, high, low_open, why)``. docs/failures.md, "Ranges of values", lists them.
RANGES: dict[str, tuple[float, float, bool, str]] = {
    "sensor_timeout": (0.0, MAX_DURATION_S, True, "seconds; an int64 of nanoseconds (clock-jump threshold)"),
    "future_tolerance": (0.0, MAX_DURATION_S, True, "seconds; an int64 of nanoseconds added to the node clock"),
    "pairing_timeout": (0.0, MAX_DURATION_S, True, "seconds; an rclpy timer period"),
    "diagnostics_period": (MIN_TIMER_PERIOD_S, MAX_DURATION_S, False, "seconds; an rclpy timer period"),
    "e0": (0.0, MAX_MAGNITUDE, False, "squared in the exact bound's ellipsoid"),
    "initial_estimate": (-MAX_MAGNITUDE, MAX_MAGNITUDE, False, "each entry; squared in the rounding bound"),
    "noise.max": (-math.inf, MAX_MAGNITUDE, False, "< 0: none; squared in the noise bound's ellipsoid"),
    "max_abs_value": (0.0, MAX_MAGNITUDE, True, "m; a sample enters the state, whose bounds square it"),
    "noise std": (0.0, MAX_MAGNITUDE, False, "a standard deviation, squared into a covariance"),
    "rate": (0.0, MAX_RATE_HZ, False, "Hz (0: not set); samples per period also bounded by memory"),
    "reorder_window_ms": (0.0, 1000.0, False, "ms a sample waits for its channel: a wait, and up to 1024 samples held"),
    "clock_tolerance_ms": (0.0, 1000.0, False, "ms of clock error; beyond a second a sample's time is unknown"),
    "switch_horizon": (0.0, 1.0, False, "a fraction of the shortest designed residence (1: no slack for a switch "
                       "that comes early)"),
    "consistency.chi2_alpha": (0.0, 0.5, False, "a false-alarm probability per sample (0: off)"),
}


def _fmt(x: float) -> str:
    return f"{x:g}"


def check_range(value: Any, name: str, *, exc: type[SwitchobsError] = InvalidArgument,
                flag: str | None = None) -> float:
    """``value`` as a float inside the documented range of ``name`` (:data:`RANGES`), else ``exc``
    with one line: the name (or the command-line ``flag`` that gave it), the range, the reason."""
    lo, hi, lo_open, why = RANGES[name]
    what = flag or f"parameter '{name}'"
    try:
        v = float(value)
    except (TypeError, ValueError, OverflowError):
        raise exc(f"{what} must be a number; got {value!r}") from None
    low_ok = v > lo if lo_open else v >= lo
    if not (math.isfinite(v) and low_ok and v <= hi):
        left = "(" if lo_open else "["
        lo_s = "-inf" if lo == -math.inf else _fmt(lo)
        raise exc(f"{what} must be in {left}{lo_s}, {_fmt(hi)}] ({why}); got {value!r}")
    return v


def check_seconds(value: Any, name: str, *, positive: bool = False,
                  exc: type[SwitchobsError] = InvalidArgument) -> float:
    """``value`` as a duration in [0, MAX_DURATION_S] s (``positive``: > 0), else ``exc`` naming ``name``
    (a tool's waits and sleeps: ``time.sleep`` and the int64 of nanoseconds take no more)."""
    try:
        v = float(value)
    except (TypeError, ValueError, OverflowError):
        raise exc(f"{name} must be a number of seconds; got {value!r}") from None
    if not (math.isfinite(v) and (v > 0 if positive else v >= 0) and v <= MAX_DURATION_S):
        raise exc(f"{name} must be in {'(' if positive else '['}0, {MAX_DURATION_S:g}] s; got {value!r}")
    return v


def fmt_bytes(n: float) -> str:
    """``n`` bytes as a short text in KiB/MiB/GiB/TiB."""
    for unit, size in (("TiB", 1 << 40), ("GiB", 1 << 30), ("MiB", 1 << 20), ("KiB", 1 << 10)):
        if n >= size:
            return f"{n / size:.3g} {unit}"
    return f"{int(n)} bytes"


def check_size(count: float, bytes_each: float, what: str, fix: str, *, budget: int = MEMORY_BUDGET_BYTES,
               exc: type[SwitchobsError] = InvalidArgument) -> int:
    """Refuse, before allocating, ``count`` items of ``bytes_each`` bytes beyond ``budget``.

    ``what`` names the items and where the count comes from ("2e+09 samples per period (rate x
    period)"), ``fix`` says what to change. Returns ``count`` as an int.
    """
    if not math.isfinite(count) or count * bytes_each > budget:
        need = count * bytes_each
        raise exc(f"{what} would need {fmt_bytes(need) if math.isfinite(need) else 'unbounded memory'}, beyond "
                  f"the budget of {fmt_bytes(budget)}: {fix}")
    return int(count)


def check_count(count: int, what: str, limit: int, *, exc: type[SwitchobsError] = InvalidArgument) -> int:
    """Refuse ``count`` above ``limit`` with one line naming ``what``."""
    if count > limit:
        raise exc(f"{what}: {count} given, at most {limit} supported")
    return count
