"""BLAS threading for small dense matrices.

switchobs works with small matrices (12 x 12 for the paper's model, 24 x 24 augmented
exponentials). Multi-threaded BLAS never helps at that size, and on a loaded or small
machine it hurts badly: measured here on 2 cores, once Clarabel has solved an SDP in the
process, every later ``scipy.linalg.expm`` of a 24 x 24 matrix took 7.9 ms instead of
31 us (OpenBLAS worker threads contending for the cores). Processes that design gains
and then run an observer (the estimator node, the CLI, the tests) therefore call
:func:`single_threaded_blas` once at start. The library itself does not change process
state on import; applications decide.

A console script that starts before numpy and scipy are imported calls
:func:`single_thread_before_load` instead of paying threadpoolctl's look through every loaded
library (about 8 ms with rclpy's): the thread counts OpenBLAS, MKL and BLIS read when they load
are set to 1 in the environment, and :func:`single_threaded_blas` has nothing left to do.
"""

from __future__ import annotations

import os
import sys

__all__ = ["BLAS_THREAD_VARIABLES", "single_thread_before_load", "single_threaded_blas"]

#: What OpenBLAS, MKL and BLIS read for their thread count when they load.
BLAS_THREAD_VARIABLES = ("OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "BLIS_NUM_THREADS")

_set_before_load = False


def single_thread_before_load() -> bool:
    """One BLAS thread, set in the environment before any BLAS is loaded (neither numpy nor scipy
    imported yet); False, changing nothing, once one of them is."""
    global _set_before_load
    if "numpy" in sys.modules or "scipy" in sys.modules:
        return False
    for name in BLAS_THREAD_VARIABLES:
        os.environ[name] = "1"
    _set_before_load = True
    return True


def single_threaded_blas() -> bool:
    """Limit BLAS/LAPACK to one thread for the rest of the process.

    Returns True if a limit was applied (by :func:`single_thread_before_load`, or now through
    threadpoolctl when it is installed), False otherwise.
    """
    if _set_before_load:
        return True
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:  # pragma: no cover - threadpoolctl is a declared dependency
        return False
    threadpool_limits(limits=1, user_api="blas")
    return True
