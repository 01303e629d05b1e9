"""BLAS threading for small dense matrices.

switchobs works with small matrices (12 x 12 for the paper's model, 24 x 24 augmented
exponentials). Multi-threaded BLAS never helps at that size, and on a loaded or small
machine it hurts badly: measured here on 2 cores, once Clarabel has solved an SDP in the
process, every later ``scipy.linalg.expm`` of a 24 x 24 matrix took 7.9 ms instead of
31 us (OpenBLAS worker threads contending for the cores). Processes that design gains
and then run an observer (the estimator node, the CLI, the tests) therefore call
:func:`single_threaded_blas` once at start. The library itself does not change process
state on import; applications decide.
"""

from __future__ import annotations

__all__ = ["single_threaded_blas"]


def single_threaded_blas() -> bool:
    """Limit BLAS/LAPACK to one thread for the rest of the process.

    Returns True if a limit was applied (threadpoolctl is installed), False otherwise.
    """
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:  # pragma: no cover - threadpoolctl is a declared dependency
        return False
    threadpool_limits(limits=1, user_api="blas")
    return True
