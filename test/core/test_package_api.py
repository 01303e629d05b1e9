"""The top-level package re-exports every library module's public names and stays light."""

from __future__ import annotations

import math
import subprocess
import sys

import switchobs_core as so
from switchobs_core.design import lmi as design
from switchobs_core.model import scenarios
from switchobs_core.runtime import observer
from switchobs_core.table import gains


def test_every_public_name_resolves_at_top_level():
    assert len(so.__all__) == len(set(so.__all__))
    for m in so.MODULES:
        for name in m.__all__:
            if name == "simulate":          # so.simulate is the module; its function is so.simulate.simulate
                continue
            assert getattr(so, name) is getattr(m, name), (m.__name__, name)
    assert so.design_table is design.design_table
    assert so.SwitchedObserver is observer.SwitchedObserver
    assert so.GainTable is gains.GainTable
    assert so.load_system is scenarios.load_system
    assert so.simulate.simulate.__module__ == "switchobs_core.sim.simulate"


def test_top_level_api_runs_the_paper_model():
    system = so.load_system("paper")
    assert (system.n, system.N) == (12, 2)
    # the paper's cycle factor through the top-level name equals the formula
    assert so.cycle_factor(2.0, 0.5, 1.5, 1.2, 0.8) == 2.0 * math.exp(0.5 * 0.8 - 1.5 * 1.2)


def test_import_does_not_load_cvxpy_or_matplotlib():
    code = "import sys, switchobs_core; print(sorted(m for m in ('cvxpy', 'matplotlib', 'rclpy') if m in sys.modules))"
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert res.returncode == 0, res.stderr
    assert res.stdout.strip() == "[]"


def test_a_submodule_imports_without_the_design_stack_and_names_come_on_first_use():
    """``import switchobs_core.exceptions`` (what every module pays) imports neither the design nor the
    certificate stack nor scipy's optimisers; the first top-level name read binds every re-export."""
    code = ("import sys, switchobs_core.exceptions, switchobs_core.runtime.observer as o\n"
            "heavy = ('switchobs_core.design.synthesis', 'switchobs_core.sim', 'scipy.optimize', 'scipy.interpolate')\n"
            "print(sorted(m for m in heavy if m in sys.modules))\n"
            "import switchobs_core as so\n"
            "print(so.SwitchedObserver is o.SwitchedObserver, 'design_table' in so.__all__, "
            "'switchobs_core.design.synthesis' in sys.modules)\n")
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert res.returncode == 0, res.stderr
    assert res.stdout.split("\n")[:2] == ["[]", "True True True"]
