"""The estimator's heap, kept by the process between samples: glibc's malloc is told once, when the
node's console script starts, not to hand freed memory back to the kernel after each sample.

glibc serves a request of at least its mmap threshold (128 KiB at start) with a mapping of its own,
unmapped again on free, and adjusts itself: a freed mapping larger than the threshold raises it to
that size (up to 32 MiB), and the trim threshold (the free memory at the heap's top that ``free``
returns to the kernel) to twice that. At n = 132 an n x n matrix is 139 KB and the covariance
message as many bytes: a sample's temporaries freed together at the heap's top exceed the trim
threshold, are returned, and the next sample touches that memory again, a minor page fault per
4 KiB page, each zeroed by the kernel. In the live 32-agent node about half of its faults were these
(bench/RESULTS.md, with the glibc settings below given through ``GLIBC_TUNABLES``; the other half
is the lazily read table's memory, each phase's prior read on its first visit).

:func:`keep_heap` sets the mmap threshold to 32 MiB (glibc's own ceiling for the adjusted one) and
the trim threshold to 64 MiB (twice that, glibc's own ratio): requests below 32 MiB come from the
heap, and the heap keeps up to 64 MiB of free memory at its top for the next sample instead of
returning it; the memory a sample uses is faulted in once. Both are set because setting either
ends glibc's adjustment: the trim threshold alone leaves the mmap threshold at 128 KiB, and every
n x n temporary is mapped and unmapped (twice the faults, measured in process).

It is a process-wide setting of the C library, so it belongs to the process's start (the console
script, :mod:`switchobs_ros.entry`), made once, before the node's imports and its DDS participant.
Where the environment already sets glibc's malloc (a ``MALLOC_*_`` threshold variable or
``GLIBC_TUNABLES`` with ``glibc.malloc.``), that choice stands and nothing is changed. With a C
library other than glibc (musl, macOS) nothing is done.
"""

from __future__ import annotations

import os
from collections.abc import Mapping

__all__ = ["MMAP_THRESHOLD", "TRIM_THRESHOLD", "applied", "keep_heap", "user_configured"]

#: Requests of this many bytes or more are mapped (glibc's ceiling for its adjusted threshold).
MMAP_THRESHOLD = 32 << 20
#: Free memory at the heap's top beyond this is returned to the kernel (twice the mmap threshold).
TRIM_THRESHOLD = 64 << 20

_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3       # mallopt's parameters (malloc.h)
_ENVIRONMENT = ("MALLOC_MMAP_THRESHOLD_", "MALLOC_TRIM_THRESHOLD_", "MALLOC_TOP_PAD_", "MALLOC_MMAP_MAX_")

#: What :func:`keep_heap` set in this process (``{"mmap_threshold": bytes, "trim_threshold": bytes}``),
#: None until it ran or when it changed nothing.
applied: dict[str, int] | None = None


def user_configured(environ: Mapping[str, str]) -> bool:
    """Whether ``environ`` sets glibc's malloc thresholds itself (then :func:`keep_heap` leaves them)."""
    return any(k in environ for k in _ENVIRONMENT) or "glibc.malloc." in environ.get("GLIBC_TUNABLES", "")


def keep_heap(environ: Mapping[str, str] = os.environ) -> dict[str, int] | None:
    """Set glibc's mmap and trim thresholds (module docstring); what was set, or None: not glibc,
    or the environment sets them (:func:`user_configured`)."""
    global applied
    if user_configured(environ):
        return None
    try:
        if not (os.confstr("CS_GNU_LIBC_VERSION") or "").startswith("glibc"):
            return None
    except (ValueError, OSError, AttributeError):       # no such name: not glibc
        return None
    import ctypes
    try:
        mallopt = ctypes.CDLL(None).mallopt
    except (OSError, AttributeError):
        return None
    mallopt.argtypes, mallopt.restype = (ctypes.c_int, ctypes.c_int), ctypes.c_int
    done = {name: value for name, param, value in (("mmap_threshold", _M_MMAP_THRESHOLD, MMAP_THRESHOLD),
                                                   ("trim_threshold", _M_TRIM_THRESHOLD, TRIM_THRESHOLD))
            if mallopt(param, value) == 1}
    applied = done or None
    return applied
