"""scipy imported without the numpy submodules that its array-API namespace copies and nothing uses,
and without rewriting the docstrings of its functions.

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

scipy's decorators also rewrite the docstring of every function they wrap as it is defined (a note on
array-API support or batching appended: ``scipy._lib._docscrape`` parses each docstring, 77 of them
for ``scipy.linalg`` and ``scipy.sparse``, 171 with ``scipy.special``: about 35 ms of a start with it). During
:func:`import_scipy` that module is a stand-in (:func:`_docs_kept`, :class:`_Docstring`: every
section empty, the docstring given back as it was), removed again afterwards; the scipy modules that
bound the stand-in by name get scipy's own parser at its first use (:func:`_function_doc`), so a
module imported later (``scipy.stats``, ``scipy.signal``) is documented as after a plain import.
What the decorators do to the functions (their wrappers, the capability tables) is unchanged; only
the notes of ``scipy.linalg`` and ``scipy.sparse`` are missing from ``help()`` (``scipy.special``,
imported later by the chi-square gate, :mod:`switchobs_core.runtime.gate`, has its notes).
"""

from __future__ import annotations

import sys
import types
from collections import defaultdict, namedtuple
from typing import Any

import numpy

__all__ = ["NOT_ARRAY_API", "import_scipy"]

#: numpy's lazily imported submodules that are not part of the array API namespace.
NOT_ARRAY_API = frozenset({"f2py", "testing", "test", "ma", "polynomial", "ctypeslib", "rec", "char", "strings",
                           "core"})

#: The module whose import copies numpy's namespace.
COPY = "scipy._lib.array_api_compat.numpy"
#: scipy's docstring parser, replaced by a stand-in during :func:`import_scipy`.
DOCSCRAPE = "scipy._lib._docscrape"


class _Docstring:
    """What scipy's decorators use of ``FunctionDoc(f)``: sections to append to (kept apart, not
    written back) and ``str()``, a signature line and ``f``'s docstring as it was."""

    def __init__(self, func: Any, *args: Any, **kwargs: Any) -> None:
        doc = getattr(func, "__doc__", None) or ""
        if isinstance(func, numpy.ufunc):   # numpy's generated signature line first, then the ufunc's own text
            doc = doc.split("\n\n", 1)[-1]
        self._doc = doc
        self._sections: defaultdict[str, list] = defaultdict(list)

    def __getitem__(self, key: str) -> list:
        return self._sections[key]

    def __setitem__(self, key: str, value: list) -> None:
        self._sections[key] = value

    def __str__(self) -> str:
        return "\n" + self._doc


def _function_doc(func: Any, *args: Any, **kwargs: Any) -> Any:
    """scipy's own ``FunctionDoc``, imported at its first use: the scipy modules that bound the
    stand-in while scipy was imported use this, so a module imported later (``scipy.stats``,
    ``scipy.signal``) gets its docstrings written as a plain import writes them."""
    from scipy._lib._docscrape import FunctionDoc
    return FunctionDoc(func, *args, **kwargs)


def _docs_kept() -> types.ModuleType:
    """The stand-in for :data:`DOCSCRAPE`: ``FunctionDoc`` (:class:`_Docstring`) and ``Parameter``."""
    mod = types.ModuleType(DOCSCRAPE, "scipy's docstring parser, left out while scipy is imported")
    mod.FunctionDoc = _Docstring               # type: ignore[attr-defined]
    mod.Parameter = namedtuple("Parameter", ["name", "type", "desc"])     # type: ignore[attr-defined]
    return mod


def import_scipy() -> bool:
    """Import ``scipy.linalg`` and ``scipy.sparse`` (what every estimator start needs; ``scipy.special``,
    the chi-square gate's quantile, is imported at the gate's first threshold), the namespace copy
    without :data:`NOT_ARRAY_API` and the docstrings as they are written; False (nothing changed) if the
    copy exists already.

    A scipy whose decorators need more of the parser than the stand-in gives fails the first
    import: its partly imported modules are dropped and scipy is imported again with its own
    parser (a slower start, never a failed one)."""
    if COPY in sys.modules:
        return False
    names, listing = numpy.__all__, numpy.__dict__.get("__dir__")
    numpy.__all__ = [n for n in names if n not in NOT_ARRAY_API]
    if listing is not None:
        numpy.__dir__ = lambda: [n for n in listing() if n not in NOT_ARRAY_API]
    try:
        if DOCSCRAPE in sys.modules or not _import_with_stand_in():
            _import()
    finally:
        numpy.__all__ = names
        if listing is not None:
            numpy.__dir__ = listing
    return True


def _import() -> None:
    import scipy.linalg
    import scipy.sparse  # noqa: F401


def _import_with_stand_in() -> bool:
    """:func:`_import` with :data:`DOCSCRAPE` replaced by :func:`_docs_kept`; False, and no scipy
    module left imported, if that import raised."""
    before = set(sys.modules)
    sys.modules[DOCSCRAPE] = _docs_kept()
    try:
        _import()
        return True
    except Exception:
        for name in set(sys.modules) - before:
            if name == "scipy" or name.startswith("scipy."):
                del sys.modules[name]
        return False
    finally:
        if sys.modules.get(DOCSCRAPE) is not None and not hasattr(sys.modules[DOCSCRAPE], "__file__"):
            del sys.modules[DOCSCRAPE]
        for name, mod in list(sys.modules.items()):     # the modules that bound the stand-in by name
            if name.startswith("scipy.") and getattr(mod, "FunctionDoc", None) is _Docstring:
                mod.FunctionDoc = _function_doc
        lib = sys.modules.get("scipy._lib")
        if lib is not None and isinstance(getattr(lib, "_docscrape", None), types.ModuleType) \
                and not hasattr(lib._docscrape, "__file__"):
            del lib._docscrape      # the stand-in: a later import gets scipy's own
