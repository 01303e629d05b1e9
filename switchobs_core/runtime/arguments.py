"""Checks of what the observer is given: its options, its initial state, and every sample.

Each check raises :class:`~switchobs_core.exceptions.InvalidArgument` with one line that names the
argument and what it got, and returns the value in the form the observer keeps
(:class:`~switchobs_core.runtime.observer.SwitchedObserver` calls them; nothing here keeps state).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ..exceptions import InvalidArgument

__all__ = ["HOLDS", "MAX_ABS_SAMPLE", "MODES", "check_disturbance", "check_hold", "check_noise_max", "check_options",
           "check_rows", "check_input", "check_sample", "check_set", "check_time", "check_transition", "initial_state",
           "input_change", "nonnegative"]

#: Schedule modes accepted by :class:`~switchobs_core.runtime.observer.SwitchedObserver`.
MODES = ("periodic", "sequence", "robust")
#: What may be held between samples (:mod:`switchobs_core.runtime.observer`).
HOLDS = ("innovation", "measurement")
#: Largest accepted norm of a sample (and magnitude of an input entry): beyond it the products
#: with the gains and ZOH matrices in the next step could overflow to inf (1e300 * ||Gamma L|| does).
MAX_ABS_SAMPLE = 1e150
_MAX_SQ = MAX_ABS_SAMPLE**2  # 1e300: still a finite double


def nonnegative(name: str, value: Any, shown: Any) -> float:
    """``value`` as a finite float >= 0 (the message shows ``shown``)."""
    v = float(value)
    if not (math.isfinite(v) and v >= 0):
        raise InvalidArgument(f"{name} must be a finite number >= 0; got {shown}")
    return v


def check_options(mode: str, hold: str, match_tol: Any, cache_size: Any, max_records: Any) -> float:
    """The schedule mode, the hold, the sizes; returns ``match_tol`` as a float."""
    if mode not in MODES:
        raise InvalidArgument(f"mode must be one of {MODES}; got {mode!r}")
    if hold not in HOLDS:
        raise InvalidArgument(f"hold must be one of {HOLDS}; got {hold!r}")
    tol = nonnegative("match_tol", match_tol, match_tol)
    for name, v in (("cache_size", cache_size), ("max_records", max_records)):
        if not isinstance(v, (int, np.integer)) or v < 1:
            raise InvalidArgument(f"{name} must be an integer >= 1; got {v!r}")
    return tol


def check_hold(hold: str, family: str, holds: tuple[str, ...]) -> None:
    """``hold`` is one the gain family ``family`` supports (``holds``)."""
    if hold not in holds:
        raise InvalidArgument(f"hold={hold!r} is not available with the {family!r} family "
                              f"(it holds {', '.join(holds)}); hold='measurement' applies to the LMI "
                              "family only")


def check_transition(transition: Any) -> None:
    """``transition`` is True, False or None."""
    if transition is not None and not isinstance(transition, (bool, np.bool_)):
        raise InvalidArgument(f"transition must be True, False or None; got {transition!r}")


def check_disturbance(disturbance: Any, n: int, noise_max: Any) -> Any:
    """A declared :class:`~switchobs_core.model.disturbance.Disturbance` (or None) for ``n`` states;
    an active one enters ``noise_bound``, so it needs ``noise_max`` (0 declares noise-free samples)."""
    if disturbance is None:
        return None
    B_w, w_max = getattr(disturbance, "B_w", None), getattr(disturbance, "w_max", None)
    if not isinstance(B_w, np.ndarray) or not isinstance(w_max, np.ndarray) or B_w.ndim != 2 or B_w.shape[0] != n:
        raise InvalidArgument(f"disturbance must be a Disturbance with an n x q B_w (n = {n}); got {disturbance!r:.80}")
    if disturbance.active and noise_max is None:
        raise InvalidArgument("a declared disturbance enters noise_bound: declare noise_max too "
                              "(0: noise-free samples)")
    return disturbance


def check_noise_max(noise_max: Any, N: int, rounding_bound: bool, hold: str) -> tuple[float, ...] | None:
    """``noise_max`` as one bound per channel (None: no bound declared)."""
    if noise_max is None:
        return None
    vals = np.atleast_1d(np.asarray(noise_max, dtype=object))
    if vals.ndim != 1 or vals.size not in (1, N):
        raise InvalidArgument(f"noise_max must be one number or {N} (one per channel); got {noise_max!r}")
    out = []
    for v in vals:
        if isinstance(v, (bool, np.bool_)) or not isinstance(v, (int, float, np.integer, np.floating)) \
                or not (math.isfinite(float(v)) and 0 <= float(v) <= MAX_ABS_SAMPLE):
            raise InvalidArgument(f"noise_max must be finite numbers in [0, {MAX_ABS_SAMPLE:g}]; got {noise_max!r}")
        out.append(float(v))
    if not rounding_bound or hold != "innovation":
        raise InvalidArgument("noise_max needs rounding_bound=True and hold='innovation' "
                              "(the noise bound extends the rounding-aware exact bound)")
    return tuple(out * N if len(out) == 1 else out)


def initial_state(x0: Any, t0: Any, n: int) -> tuple[np.ndarray, float]:
    """``(x_hat(t0), t0)``: ``x0`` as n finite floats (zeros for None) and a finite ``t0``."""
    t0 = float(t0)
    if not math.isfinite(t0):
        raise InvalidArgument(f"t0 must be finite; got {t0}")
    if x0 is None:
        return np.zeros(n), t0
    x = np.array(x0, dtype=float).reshape(-1)
    if x.size != n:
        raise InvalidArgument(f"x0 must have n = {n} entries; got {x.size}")
    if not np.isfinite(x).all():
        raise InvalidArgument("x0 has a non-finite entry")
    return x, t0


def check_time(t: Any, t_now: float) -> float:
    """``t - t_now`` for a finite ``t >= t_now`` (a read or a set at ``t``)."""
    dt = float(t) - t_now
    if not (math.isfinite(dt) and dt >= 0):
        raise InvalidArgument(f"t = {t!r} must be a finite time >= the observer's time {t_now!r}")
    return dt


def check_rows(rows: Any, channel: int, p: int) -> tuple | None:
    """The 0-based rows of ``C_channel`` (``p`` rows) a sample holds, None for all of them."""
    if rows is None:
        return None
    try:
        r = tuple(int(i) for i in rows)
    except (TypeError, ValueError):
        raise InvalidArgument(f"rows must be a sequence of row indices; got {rows!r}") from None
    if not r or len(set(r)) != len(r) or min(r) < 0 or max(r) >= p:
        raise InvalidArgument(f"rows must be distinct indices in 0..{p - 1} of C_{channel}'s "
                              f"rows; got {rows!r}")
    return None if r == tuple(range(p)) else r


def check_sample(t: Any, t_now: float, channel: Any, y: Any, u: Any, rows: Any, p: tuple[int, ...],
                 m: int) -> tuple[Any, np.ndarray, np.ndarray | None, tuple | None]:
    """One sample of :meth:`~switchobs_core.runtime.observer.SwitchedObserver.update`:
    ``(dt, y, u, rows)`` with ``dt = t - t_now``, ``y`` and ``u`` float vectors (``u`` None if not
    given) and the rows of :func:`check_rows`; ``p`` the channels' row counts, ``m`` the inputs."""
    dt = t - t_now
    if not dt >= 0:
        raise InvalidArgument(f"t = {t!r} is earlier than the observer's time {t_now!r} "
                              "(samples must come in time order)" if dt < 0 else
                              f"t must be a finite time; got {t!r}")
    if dt == math.inf:
        raise InvalidArgument(f"t must be a finite time; got {t!r}")
    if type(channel) is not int and (isinstance(channel, (bool, np.bool_))        # a plain int: checked
                                     or not isinstance(channel, (int, np.integer))) or not 1 <= channel <= len(p):
        raise InvalidArgument(f"channel must be an integer in 1..{len(p)}; got {channel!r}")
    try:
        y = np.asarray(y, dtype=float)
    except (TypeError, ValueError, OverflowError) as exc:       # complex, text, an int beyond a double
        raise InvalidArgument(f"y must be real numbers: {exc}") from None
    if rows is not None:
        rows = check_rows(rows, channel, p[channel - 1])
    q = p[channel - 1] if rows is None else len(rows)
    if y.shape != (q,):
        y = y.reshape(-1)
        if y.size != q:
            raise InvalidArgument(f"y must have {q} entries for channel {channel}"
                                  f"{'' if rows is None else f' rows {rows}'}; got {y.size}")
    # One norm checks both (hot path): ||y|| <= bound is False for NaN, for inf and for any entry beyond
    # the bound. math.hypot cannot overflow for a finite y and is the fastest for a few entries (0.13 us
    # at 4 against ndarray.dot's 0.3 us, max|y| 2 us); above 16 entries y'y, its overflow kept quiet.
    if q and not (math.hypot(*y.tolist()) <= MAX_ABS_SAMPLE if q <= 16 else _quiet_sq(y) <= _MAX_SQ):
        if not np.isfinite(y).all():
            raise InvalidArgument(f"y has a non-finite entry: {y.tolist()}")
        raise InvalidArgument(f"y is too large (||y|| = {math.hypot(*y.tolist()):.3g} > {MAX_ABS_SAMPLE:g}): "
                              "the update would overflow")
    return dt, y, None if u is None else check_input(u, m), rows


def _quiet_sq(y: np.ndarray) -> float:
    """``y'y``, ``inf`` where it overflows, without numpy's warning."""
    with np.errstate(over="ignore", invalid="ignore"):
        return float(y.dot(y))


def check_input(u: Any, m: int) -> np.ndarray:
    """The input ``u`` as a float vector of the system's ``m`` entries, finite and at most
    :data:`MAX_ABS_SAMPLE` in magnitude."""
    u = np.asarray(u, dtype=float).reshape(-1)
    if u.size != m or not np.isfinite(u).all() or (u.size and np.abs(u).max() > MAX_ABS_SAMPLE):
        raise InvalidArgument(f"u must hold {m} finite entries of magnitude <= {MAX_ABS_SAMPLE:g}; "
                              f"got {u.tolist()}")
    return u


def input_change(u: Any, m: int, held: np.ndarray | None) -> tuple[bool, np.ndarray | None]:
    """``(changed, u)``: the checked input to hold (None for zero) and whether it differs from ``held``."""
    u = None if u is None else check_input(u, m)
    u = u if u is not None and u.any() else None
    same = (u is None) == (held is None) and (u is None or np.array_equal(u, held))
    return not same, u


def check_set(t: Any, t_now: float, values: dict, variances: dict | None, n: int) -> float:
    """What :meth:`~switchobs_core.runtime.observer.SwitchedObserver.set_estimate` is given:
    ``t >= t_now``, state indices in ``0..n-1``, finite values, variances >= 0; returns ``t - t_now``."""
    dt = check_time(t, t_now)
    for i, v in list(values.items()) + list((variances or {}).items()):
        if not (isinstance(i, (int, np.integer)) and 0 <= i < n):
            raise InvalidArgument(f"state index {i!r} out of range 0..{n - 1}")
        if not math.isfinite(float(v)) or abs(float(v)) > MAX_ABS_SAMPLE:
            raise InvalidArgument(f"value {v!r} for state {i} must be finite (|v| <= {MAX_ABS_SAMPLE:g})")
    if any(float(v) < 0 for v in (variances or {}).values()):
        raise InvalidArgument("variances must be >= 0")
    return dt
