"""scipy imported without the numpy submodules that its array-API namespace copies and nothing uses.

``import scipy.linalg`` makes ``scipy._lib.array_api_compat.numpy``, a copy of numpy's namespace
(``from numpy import *`` and every name of ``dir(numpy)``); numpy imports its public submodules
lazily, on first access, and both lists name all of them, so the copy imports ``numpy.f2py``,
``numpy.testing`` (with ``unittest``), ``numpy.ma``, ``numpy.polynomial``, ... : 60-90 ms of a
node's start (bench/RESULTS.md), for attributes that scipy reads only on CuPy's and PyTorch's
namespaces (``xp.testing``), never on numpy's. :func:`import_scipy` makes that copy with
:data:`NOT_ARRAY_API` left out of both lists, then puts numpy's lists back: numpy itself is
unchanged (``numpy.testing`` and the others still import on first access), and so is every array
function of the copy. Like :mod:`switchobs_core.threads`, importing this module changes nothing:
the application decides (the nodes' console scripts, :mod:`switchobs_ros.entry`, call it before they
import the node); a process that imported scipy already keeps its copy as it is.
"""

from __future__ import annotations

import sys

import numpy

__all__ = ["NOT_ARRAY_API", "import_scipy"]

#: numpy's lazily imported submodules that are not part of the array API namespace.
NOT_ARRAY_API = frozenset({"f2py", "testing", "test", "ma", "polynomial", "ctypeslib", "rec", "char", "strings",
                           "core"})

#: The module whose import copies numpy's namespace.
COPY = "scipy._lib.array_api_compat.numpy"


def import_scipy() -> bool:
    """Import ``scipy.linalg``, ``scipy.sparse`` and ``scipy.special`` (what every estimator start
    needs), the namespace copy without :data:`NOT_ARRAY_API`; False (nothing changed) if the copy
    exists already."""
    if COPY in sys.modules:
        return False
    names, listing = numpy.__all__, numpy.__dict__.get("__dir__")
    numpy.__all__ = [n for n in names if n not in NOT_ARRAY_API]
    if listing is not None:
        numpy.__dir__ = lambda: [n for n in listing() if n not in NOT_ARRAY_API]
    try:
        import scipy.linalg
        import scipy.sparse
        import scipy.special  # noqa: F401
    finally:
        numpy.__all__ = names
        if listing is not None:
            numpy.__dir__ = listing
    return True
