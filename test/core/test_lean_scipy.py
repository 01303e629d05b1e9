"""scipy imported by the nodes' console scripts (:mod:`switchobs_core.lean_scipy`): its copy of numpy's
namespace made without numpy's submodules outside the array API, numpy itself left as it was, and
the scipy functions the estimator calls giving the same bytes as after a plain import."""

from __future__ import annotations

import json
import subprocess
import sys

from switchobs_core.lean_scipy import NOT_ARRAY_API

#: Prints, as JSON: what import_scipy returned (twice), numpy's lists before and after, the submodules
#: imported, the copy's names, and the bytes (hex) of scipy results the estimator relies on.
PROBE = """
import json, sys
import numpy as np
all_before, dir_before = list(np.__all__), dir(np)
lean = sys.argv[1] in ("lean", "broken")
if sys.argv[1] == "broken":     # a stand-in that scipy's decorators cannot use
    import types
    import switchobs_core.lean_scipy as lean_scipy
    lean_scipy._docs_kept = lambda: types.ModuleType(lean_scipy.DOCSCRAPE)
if lean:
    from switchobs_core.lean_scipy import import_scipy
    first, second = import_scipy(), import_scipy()
else:
    import scipy.linalg, scipy.sparse, scipy.special
    first = second = None
loaded = sorted(m for m in sys.modules if m.startswith("numpy.") and m.count(".") == 1)    # before any call
parser_left = "scipy._lib._docscrape" in sys.modules
special_at_start = "scipy.special" in sys.modules
import scipy._lib.array_api_compat.numpy as copy
from scipy.linalg import cholesky, expm, matrix_balance
from scipy.special import chdtri
from scipy.sparse import csr_array
rng = np.random.default_rng(7)
A = rng.standard_normal((12, 12))
out = [expm(A).tobytes().hex(), matrix_balance(A)[0].tobytes().hex(), np.float64(chdtri(4, 1e-3)).tobytes().hex(),
       (csr_array(np.triu(A)) @ A).tobytes().hex()]
print(json.dumps({"first": first, "second": second, "all_same": list(np.__all__) == all_before,
                  "dir_same": dir(np) == dir_before,
                  "loaded": loaded,
                  "copy": sorted(n for n in dir(copy) if not n.startswith("_")), "out": out,
                  "testing_later": __import__("numpy.testing").testing.assert_array_equal is not None,
                  "parser_left": parser_left, "special_at_start": special_at_start,
                  "later_doc": __import__("scipy.signal").signal.convolve.__doc__,
                  "expm_doc": expm.__doc__, "cholesky_doc": cholesky.__doc__, "chdtri_doc": chdtri.__doc__,
                  "parser_later": __import__("scipy._lib._docscrape").
                  _lib._docscrape.FunctionDoc(expm)["Summary"]}))
"""


def _probe(mode: str) -> dict:
    res = subprocess.run([sys.executable, "-c", PROBE, mode], capture_output=True, text=True, timeout=120)
    assert res.returncode == 0, res.stderr
    return json.loads(res.stdout)


def test_namespace_copy_without_the_submodules_and_numpy_unchanged():
    """The lean import leaves out exactly numpy's non-array-API submodules: none of them is imported by it
    (scipy's own functions may import one later, as ``matrix_balance`` imports ``numpy.ma``),
    the copy lacks only those names (every other name of a plain import's copy is there), numpy's
    ``__all__`` and ``dir`` are what they were, ``numpy.testing`` still imports when asked; expm, the
    balancing, the chi-square quantile and a sparse product give the same bytes; a second call is a no-op."""
    lean, plain = _probe("lean"), _probe("plain")
    assert (lean["first"], lean["second"]) == (True, False)
    assert lean["all_same"] and lean["dir_same"] and lean["testing_later"]
    assert not {f"numpy.{m}" for m in NOT_ARRAY_API} & set(lean["loaded"]), lean["loaded"]
    assert {f"numpy.{m}" for m in ("f2py", "testing")} <= set(plain["loaded"])      # what the plain copy imports
    missing = set(plain["copy"]) - set(lean["copy"])
    assert missing and missing <= NOT_ARRAY_API, missing
    assert set(lean["copy"]) <= set(plain["copy"])
    assert lean["out"] == plain["out"]


def test_docstrings_kept_as_written_and_the_parser_imported_later():
    """The lean import leaves scipy's docstring parser out (no module left behind): the functions keep
    the docstrings they were written with (the plain import appends scipy's notes to the same text, as to
    ``cholesky``'s), and a later import of the parser gets scipy's own, which parses. ``scipy.special`` is not
    imported (the chi-square gate imports it at its first threshold, with scipy's notes)."""
    lean, plain = _probe("lean"), _probe("plain")
    assert not lean["parser_left"] and plain["parser_left"]
    for name in ("expm_doc", "cholesky_doc"):
        first = lean[name].strip().splitlines()[0]
        assert first and first in plain[name], (name, first)
    assert len(lean["cholesky_doc"]) < len(plain["cholesky_doc"])      # without scipy's array-API note
    # scipy.special is left to the chi-square gate's first threshold: imported then, with scipy's notes
    assert not lean["special_at_start"] and plain["special_at_start"]
    assert lean["chdtri_doc"] == plain["chdtri_doc"]
    assert lean["parser_later"] == plain["parser_later"] == ["Compute the matrix exponential of an array."]
    assert lean["later_doc"] == plain["later_doc"]      # a module imported later: scipy's own notes
    assert "Array API Standard Support" in plain["later_doc"]


def test_a_stand_in_scipy_cannot_use_falls_back_to_scipys_parser():
    """If scipy's import fails with the stand-in (a scipy whose decorators need more of the parser),
    the partly imported modules are dropped and scipy is imported with its own parser: the same
    results and docstrings as a plain import, the namespace copy still lean."""
    broken, plain = _probe("broken"), _probe("plain")
    assert (broken["first"], broken["second"]) == (True, False)
    assert broken["parser_left"]
    assert broken["out"] == plain["out"]
    assert broken["chdtri_doc"] == plain["chdtri_doc"]
    assert not {f"numpy.{m}" for m in NOT_ARRAY_API} & set(broken["loaded"]), broken["loaded"]
