"""What the estimator's start imports: neither its module nor the pipeline built from a cached table
brings in what only a design, a simulation, a plot or a test needs.

One fresh interpreter starts as the ``estimator`` console script does up to its node (message type
support without rosidl's code generator, :func:`switchobs_ros.early.type_support_only`; scipy through
:mod:`switchobs_core.lean_scipy`, then the node's module and an output's type support), then builds
the pipeline from a Kalman table on disk (:meth:`~switchobs_ros.pipeline.EstimatorPipeline.from_params`,
no DDS; a Kalman table and an LMI table), and prints the modules loaded after each step. None of
:data:`HEAVY` may be among them (rclpy itself imports ``yaml``, so it is not checked here).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from switchobs_core.design.kalman import design_kalman
from switchobs_core.design.lmi import design_table
from switchobs_core.model.scenarios import paper_system
from switchobs_core.model.schedule import Cycle
from switchobs_core.table.gains import kalman_table

REPO = Path(__file__).resolve().parents[2]

#: Modules (and their submodules) a start from a cached table has no use for: the SDP and Riccati
#: design stack, the simulator and the command line, plotting, scipy's optimisers, statistics,
#: integrators and interpolants, numpy's submodules outside the array API, the test framework, and
#: scipy's docstring parser (:mod:`switchobs_core.lean_scipy`), the RViz markers' message classes (made after
#: the first estimate: :mod:`switchobs_ros.late_markers`), and ``scipy.special`` (the chi-square gate's
#: quantile, imported at the gate's first threshold: :mod:`switchobs_core.runtime.gate`).
HEAVY = ("cvxpy", "clarabel", "matplotlib", "switchobs_core.design.lmi", "switchobs_core.design.kalman",
         "switchobs_core.design.synthesis", "switchobs_core.design.plan", "switchobs_core.design.doubling",
         "switchobs_core.sim", "switchobs_core.cli", "scipy.optimize", "scipy.stats", "scipy.integrate",
         "scipy.interpolate", "numpy.f2py", "numpy.testing", "numpy.ma", "numpy.polynomial", "unittest",
         "scipy._lib._docscrape", "rosidl_generator_py.generate_py_impl", "rosidl_parser.parser", "lark", "em",
         "rosidl_pycommon", "visualization_msgs", "scipy.special")

PROBE = """
import json, sys
from switchobs_ros import early
early.type_support_only()
from switchobs_core.lean_scipy import import_scipy
import_scipy()
import switchobs_ros.estimator
from nav_msgs.msg import Odometry
from rclpy.type_support import check_for_type_support
check_for_type_support(Odometry)
imported = sorted(sys.modules)
from switchobs_ros.pipeline import EstimatorPipeline
pipe = EstimatorPipeline.from_params({"system": "paper", "gain_table": sys.argv[1], "schedule.mode": "periodic",
                                      "schedule.tau": [2.0], "schedule.s": [0.6]})
built = sorted(sys.modules)
from rosidl_generator_py.generate_py_impl import generate_py
print(json.dumps({"imported": imported, "built": built, "family": pipe.observer.family,
                  "generator": callable(generate_py)}))
"""


def _heavy(modules: list[str]) -> list[str]:
    return [m for m in modules if any(m == h or m.startswith(h + ".") for h in HEAVY)]


@pytest.fixture(scope="module", params=["kalman", "lmi"])
def loaded(request, tmp_path_factory) -> dict:
    system, cycle = paper_system(), Cycle.from_ts(2.0, 0.6)
    where = tmp_path_factory.mktemp("imports")
    if request.param == "kalman":
        path = kalman_table(system, [design_kalman(system, cycle, 50.0)]).save(where / "paper_kalman.npz")
    else:
        path = design_table(system, [cycle], progress=False).save(where / "paper_lmi.json")
    env = dict(os.environ, PYTHONPATH=str(REPO))
    res = subprocess.run([sys.executable, "-c", PROBE, str(path)], capture_output=True, text=True, timeout=120,
                         env=env, cwd=str(REPO))
    assert res.returncode == 0, res.stderr
    return dict(json.loads(res.stdout.strip().splitlines()[-1]), expected=request.param)


def test_the_node_module_imports_nothing_heavy(loaded):
    """...and its outputs' type support comes without rosidl's code generator, which a later import still
    gets whole."""
    assert "switchobs_ros.estimator" in loaded["imported"]
    assert "nav_msgs.nav_msgs_s__rosidl_typesupport_c" in loaded["imported"]
    assert loaded["generator"] is True
    assert not _heavy(loaded["imported"]), _heavy(loaded["imported"])


def test_the_pipeline_from_a_cached_table_imports_nothing_heavy(loaded):
    """The table's load, its check, the system's decompositions, the observer (the table's family) and
    the pipeline's set-up: none imports the design stack or the others."""
    assert loaded["family"] == loaded["expected"]
    assert not _heavy(loaded["built"]), _heavy(loaded["built"])


def test_the_probe_sees_a_heavy_import():
    """The same check catches a heavy module once something imports it (here: the design of a table)."""
    code = ("import sys; from switchobs_core.lean_scipy import import_scipy; import_scipy(); "
            "import switchobs_core.design.kalman; print('\\n'.join(sorted(sys.modules)))")
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120,
                         env=dict(os.environ, PYTHONPATH=str(REPO)), cwd=str(REPO))
    assert res.returncode == 0, res.stderr
    assert "switchobs_core.design.kalman" in _heavy(res.stdout.split())


def test_the_bag_tool_freezes_its_imports_only_as_a_console_script():
    """The bag tool's console script (``switchobs_ros.entry.switchobs_bag``) imports with garbage
    collection off and freezes what the imports made; a library importing ``switchobs_ros.bag.cli`` keeps
    its own collection (nothing frozen, collection on)."""
    code = r"""
import gc, json, sys
import switchobs_ros.entry as entry
out = {"before": [gc.isenabled(), gc.get_freeze_count()]}
import switchobs_ros.bag.cli
out["library"] = [gc.isenabled(), gc.get_freeze_count()]
sys.modules.pop("switchobs_ros.bag.cli")
seen = []
class Probe:
    @staticmethod
    def main():
        seen.append([gc.isenabled(), gc.get_freeze_count()])
        return 0
import importlib
real = importlib.import_module
importlib.import_module = lambda name: (seen.append(gc.isenabled()), real(name), Probe)[2]
rc = entry._run("bag.cli", "switchobs_bag", frozen_imports=True)
out["console"] = [rc, *seen]
print(json.dumps(out))
"""
    repo = str(Path(__file__).resolve().parents[2])
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([repo, os.environ.get("PYTHONPATH", "")]))
    got = json.loads(subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True,
                                    check=True, timeout=120).stdout.strip().splitlines()[-1])
    assert got["before"] == [True, 0]
    assert got["library"] == [True, 0]                 # imported as a library: nothing frozen
    rc, during, (after_on, frozen) = got["console"]
    assert rc == 0 and during is False                 # the module imported with collection off
    assert after_on is True and frozen > 1000          # then frozen, and collection on again
