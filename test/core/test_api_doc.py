"""Every name docs/api.md documents exists: its imports resolve and every attribute it shows
on a documented object exists on a real instance."""

from __future__ import annotations

import importlib
import re
from pathlib import Path

import numpy as np
import pytest
from _paper_designs import paper_table

import switchobs_core as so
from switchobs_core.model.schedule import Cycle, PeriodicSchedule
from switchobs_core.runtime.observer import SwitchedObserver
from switchobs_core.sim.plant import Plant

DOC = Path(__file__).resolve().parents[2] / "docs" / "api.md"


def _code() -> str:
    return "\n".join(re.findall(r"```python\n(.*?)```", DOC.read_text(), re.S))


def test_documented_imports_resolve():
    imports = re.findall(r"^from (switchobs_core[\w.]*) import ([\w, ]+?)\s*(?:#.*)?$", _code(), re.M)
    assert len(imports) >= 8
    for mod, names in imports:
        m = importlib.import_module(mod)
        for name in (n.strip() for n in names.split(",")):
            assert hasattr(m, name), f"{mod}.{name}"


@pytest.fixture(scope="module")
def objects(paper):
    table = paper_table(paper, robust=(0.8, 1.2))
    c = Cycle.from_ts(2.0, 0.6)
    kd = so.design_kalman(paper, [c], 50.0)
    ktable = so.kalman_table(paper, [kd])
    return {
        "so": so, "sys": paper, "table": table, "c": c, "d": table.lookup(c),
        "schedule": PeriodicSchedule(c), "obs": SwitchedObserver(paper, table, cycles=[c]),
        "plant": Plant(paper, np.zeros(paper.n)), "so.simulate": so.simulate, "so.paper": so.paper,
        "kd": kd, "ktable": ktable, "noise": kd.noise,
    }


def test_documented_attributes_exist_on_real_objects(objects):
    code = _code()
    names = r"so\.simulate|so\.paper|so|sys|table|ktable|kd|noise|c|d|schedule|obs|plant"
    uses = re.findall(rf"(?<![\w.])((?:{names}))\.(\w+)", code)
    assert len(uses) >= 40
    missing = [f"{var}.{attr}" for var, attr in uses if not hasattr(objects[var], attr)]
    assert not missing, missing
    # the classes documented by name are the top-level ones
    for name in ("Cycle", "GainTable", "CycleDesign", "SwitchedObserver", "Plant", "Residence", "CycleRecord"):
        assert hasattr(so, name), name
