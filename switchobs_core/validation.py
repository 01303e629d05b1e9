"""Argument checking shared by every public entry point of switchobs_core.

Each matrix argument goes through :func:`as_matrix` once, at the entry, and the
message names the argument and says what was expected (python-control's
``_ssmatrix`` convention).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from .exceptions import InvalidArgument

__all__ = ["as_matrix", "as_vector", "as_positive", "as_finite", "MAX_ABS_SYSTEM_ENTRY"]

#: Largest magnitude of an entry of A, B or C_i. Beyond it the design's SDPs are out of the
#: solvers' range (1e300 made SCS fail to allocate), and no physical model needs it: rescale
#: the state or the time unit instead.
MAX_ABS_SYSTEM_ENTRY = 1e12


def as_matrix(
    M: ArrayLike,
    name: str,
    *,
    rows: int | None = None,
    cols: int | None = None,
    square: bool = False,
    exc: type[InvalidArgument] = InvalidArgument,
    max_abs: float | None = None,
) -> np.ndarray:
    """Return ``M`` as a finite 2-D float64 array, or raise ``exc`` naming ``name``
    (also when an entry exceeds ``max_abs`` in magnitude, if given)."""
    try:
        arr = np.array(M, dtype=float)
    except (TypeError, ValueError) as err:
        raise exc(f"{name} must be a numeric matrix ({err})") from None
    if arr.ndim == 1 and (rows == 1 or cols is not None and arr.size == cols and rows is None):
        arr = arr.reshape(1, -1)
    if arr.ndim != 2:
        raise exc(f"{name} must be a 2-D matrix; got an array with {arr.ndim} dimension(s)")
    if square and arr.shape[0] != arr.shape[1]:
        raise exc(f"{name} must be square; got shape {arr.shape}")
    if rows is not None and arr.shape[0] != rows:
        raise exc(f"{name} has the wrong number of rows; expected {rows}, got {arr.shape[0]}")
    if cols is not None and arr.shape[1] != cols:
        raise exc(f"{name} has the wrong number of columns; expected {cols}, got {arr.shape[1]}")
    bad = ~np.isfinite(arr)
    if bad.any():
        i, j = np.argwhere(bad)[0]
        raise exc(f"{name} has a non-finite entry ({arr[i, j]}) at row {i}, column {j}")
    if max_abs is not None:
        big = np.abs(arr) > max_abs
        if big.any():
            i, j = np.argwhere(big)[0]
            raise exc(f"{name} has an entry of magnitude {abs(arr[i, j]):.3g} at row {i}, column {j}, beyond the "
                      f"supported {max_abs:g} (rescale the state or the time unit)")
    return arr


def as_vector(v: ArrayLike, name: str, *, size: int | None = None) -> np.ndarray:
    """Return ``v`` as a finite 1-D float64 array of the given size."""
    try:
        arr = np.array(v, dtype=float).reshape(-1)
    except (TypeError, ValueError) as err:
        raise InvalidArgument(f"{name} must be a numeric vector ({err})") from None
    if size is not None and arr.size != size:
        raise InvalidArgument(f"{name} must have {size} entries; got {arr.size}")
    if not np.all(np.isfinite(arr)):
        raise InvalidArgument(f"{name} has a non-finite entry: {arr.tolist()}")
    return arr


def as_finite(x: Any, name: str) -> float:
    """Return ``x`` as a finite float, or raise naming ``name``."""
    try:
        val = float(x)
    except (TypeError, ValueError):
        raise InvalidArgument(f"{name} must be a number; got {x!r}") from None
    if not math.isfinite(val):
        raise InvalidArgument(f"{name} must be finite; got {val}")
    return val


def as_positive(x: Any, name: str) -> float:
    """Return ``x`` as a finite float > 0, or raise naming ``name``."""
    val = as_finite(x, name)
    if val <= 0:
        raise InvalidArgument(f"{name} must be > 0; got {val}")
    return val
