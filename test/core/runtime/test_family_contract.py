"""The contract between the observer and its gain families (switchobs_core.runtime.families.base):
a family reads the observer through its FamilyContext and Sample only, and the observer applies
the Correction a family returns. Checked by reading the code (no module but the observer's own
touches the observer's private attributes; the observer names no family) and by running a
family written against the protocol alone, registered with one registry line."""

from __future__ import annotations

import ast
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
import pytest
from scipy.linalg import expm

import switchobs_core
from switchobs_core.families import REGISTRY, FamilyEntry
from switchobs_core.model.scenarios import paper_system
from switchobs_core.model.schedule import Cycle, PeriodicSchedule
from switchobs_core.runtime.families.base import OPEN_LOOP, Correction, FamilyContext, Sample, ScheduledCycle
from switchobs_core.runtime.families.online import kalman_correct
from switchobs_core.runtime.observer import SwitchedObserver

REPO = Path(switchobs_core.__file__).resolve().parents[1]
OBSERVER = REPO / "switchobs_core" / "runtime" / "observer.py"
#: Names that hold an observer in this code base (``obs``, ``self.observer``, ``pipeline.observer``, ...).
OBSERVER_NAMES = {"obs", "observer", "_obs", "_observer"}


def _names_observer(node: ast.expr) -> bool:
    """Whether ``node`` is an observer by name: ``obs``, ``observer`` or ``<anything>.obs`` / ``.observer``."""
    if isinstance(node, ast.Name):
        return node.id in OBSERVER_NAMES
    return isinstance(node, ast.Attribute) and node.attr in OBSERVER_NAMES


def _private(name: str) -> bool:
    return name.startswith("_") and not name.startswith("__")


def private_uses(path: Path, root: Path = REPO) -> list[str]:
    """``obs._x``-like accesses in ``path`` (attribute access or ``getattr(obs, "_x")``), in source order."""
    out = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Attribute) and _private(node.attr) and _names_observer(node.value):
            out.append((node.lineno, node.col_offset, ast.unparse(node)))
        elif (isinstance(node, ast.Call) and isinstance(node.func, ast.Name)
              and node.func.id in ("getattr", "setattr", "hasattr", "delattr") and len(node.args) >= 2
              and _names_observer(node.args[0]) and isinstance(node.args[1], ast.Constant)
              and isinstance(node.args[1].value, str) and _private(node.args[1].value)):
            out.append((node.lineno, node.col_offset, ast.unparse(node)))
    return [f"{path.relative_to(root)}:{line}: {text}" for line, _, text in sorted(out)]


def _modules(*packages: str) -> list[Path]:
    return [p for pkg in packages for p in sorted((REPO / pkg).rglob("*.py"))]


def test_the_scan_finds_what_it_looks_for(tmp_path):
    """The scan's own check: it reports each form of access it is meant to catch, and nothing else."""
    src = tmp_path / "m.py"
    src.write_text("obs._x\nself.observer._P\npl.observer._bound.hold()\ngetattr(obs, '_key')\n"
                   "obs.x_hat\nobs.__class__\nself._x\nctx._cache\n")
    assert private_uses(src, tmp_path) == ["m.py:1: obs._x", "m.py:2: self.observer._P", "m.py:3: pl.observer._bound",
                                           "m.py:4: getattr(obs, '_key')"]


def test_only_the_observer_touches_its_private_attributes():
    """No module of switchobs_core but runtime/observer.py, and none of msg_bridge, switchobs_ros
    or tools, reads or writes an underscore attribute of an observer."""
    paths = [p for p in _modules("switchobs_core", "msg_bridge", "switchobs_ros", "tools") if p != OBSERVER]
    assert len(paths) > 100
    found = [use for p in paths for use in private_uses(p)]
    assert found == []


def test_the_observer_names_no_family_and_the_families_no_observer():
    """The observer reaches its family through the registry and the protocol module only; a family
    module never imports the observer."""
    tree = ast.parse(OBSERVER.read_text())
    imported = {node.module for node in ast.walk(tree) if isinstance(node, ast.ImportFrom)}
    assert {m for m in imported if m and "families" in m} == {"families", "families.base"}
    names = {n.id for n in ast.walk(tree) if isinstance(n, ast.Name)}
    assert not names & {"LmiGains", "KalmanTableGains", "OnlineKalmanGains"}
    for path in (REPO / "switchobs_core" / "runtime" / "families").glob("*.py"):
        mods = {node.module for node in ast.walk(ast.parse(path.read_text())) if isinstance(node, ast.ImportFrom)}
        assert not {m for m in mods if m and m.endswith("observer")}, path


def test_runtime_modules_are_at_most_600_lines():
    for path in _modules("switchobs_core/runtime"):
        assert len(path.read_text().splitlines()) <= 600, path


# ---------------------------------------------------------------- a family from outside
class FixedGains:
    """A correcting family written against the protocol alone: at every sample on channel ``i``
    the fixed gain ``K_i = g C_i' (C_i C_i')^-1`` corrects the prediction (no covariance kept)."""

    name: ClassVar[str] = "fixed-test"
    paper_envelope: ClassVar[bool] = False
    holds: ClassVar[tuple[str, ...]] = ("innovation",)
    held = None
    kalman = None
    noise = None
    track_covariance = False
    bounds = None
    source = "table"

    def __init__(self, ctx: FamilyContext, table: Any, mode: str, cycles: Any, **_: Any) -> None:
        self._ctx = ctx
        self.designs = tuple(ScheduledCycle(c) for c in cycles)
        self.promised = tuple(cycles)
        self.K = tuple(0.5 * C.T @ np.linalg.inv(C @ C.T) for C in ctx.C)
        self._I = np.eye(ctx.n)

    def reset(self) -> None:
        return None

    def fuses(self, input_held: bool) -> bool:
        return not input_held

    def sample(self, s: Sample) -> Correction:
        e = self._ctx.zoh(OPEN_LOOP, s.dt) if s.dt > 0 else None
        x = s.x if e is None else e.Phi @ s.x
        xp, m = kalman_correct(x, self.K[s.channel - 1], self._ctx.C[s.channel - 1], s.y, self._I,
                               None if e is None else (e, s.dt, s.x))
        return Correction(xp, (m,))

    def stepped(self, e: Any, dt: float) -> None:
        return None

    def covariance(self) -> None:
        return None

    def predict_covariance(self, P: np.ndarray, e: Any, dt: float) -> np.ndarray:
        return P

    def depart(self, why: str) -> None:
        return None

    def set_covariance(self, P: np.ndarray) -> None:
        return None


@dataclass(frozen=True)
class _Entry(FamilyEntry):
    """A registry entry whose type is given directly (the test's family lives outside the package)."""

    cls: Any = None

    def type(self) -> Any:
        return self.cls


def test_a_family_written_against_the_protocol_runs_in_the_observer(monkeypatch):
    """One registry line and the observer runs it: the estimate, ``Phi`` and the exact bound follow
    the family's correction, against an independent product of ``(I - K H) e^{A dt}``."""
    monkeypatch.setitem(REGISTRY, "fixed-test", _Entry("fixed-test", "", "", "lmi", False, "test", cls=FixedGains))
    system = paper_system()
    cycle = Cycle.from_ts(2.0, 0.6)
    x0 = np.array([0, 0, 0.1, 0, 1, 2, 0.2, -0.1, -1, 3, 0, 0.2], float)
    obs = SwitchedObserver(system, None, cycles=[cycle], family="fixed-test", e0=float(np.linalg.norm(x0)),
                           transition=True)
    assert obs.family == "fixed-test" and obs.P is None and obs.gains_source == "table"
    sched = PeriodicSchedule(cycle)
    rate = 50.0
    F = expm(np.asarray(system.A) / rate)
    Phi_ref = np.eye(system.n)
    x = x0.copy()
    for k in range(1, 301):
        t = k / rate
        x = F @ x
        ch = sched.channel_at(t)
        C = np.asarray(system.C[ch - 1])
        xh = obs.update(t, ch, C @ x)
        Phi_ref = (np.eye(system.n) - obs.gains.K[ch - 1] @ C) @ F @ Phi_ref
        err = float(np.linalg.norm(xh - x))
        assert err <= obs.envelope().exact_bound
    # the error is the transition applied to the initial error (x_hat(0) = 0): e = Phi (-x0)
    assert np.allclose(obs.Phi, Phi_ref, rtol=1e-9, atol=1e-12)
    assert np.allclose(xh - x, Phi_ref @ (-x0), rtol=1e-8, atol=1e-12)


def test_a_family_is_given_the_context_not_the_observer():
    """What a family is constructed with: the context (the observer's matrices, hold and ZOH cache
    methods), never the observer."""
    system = paper_system()
    seen = {}

    class Spy(FixedGains):
        def __init__(self, ctx: FamilyContext, *a: Any, **kw: Any) -> None:
            super().__init__(ctx, *a, **kw)
            seen["args"] = (ctx, *a, *kw.values())

    entry = _Entry("spy-test", "", "", "lmi", False, "test", cls=Spy)
    with pytest.MonkeyPatch.context() as mp:
        mp.setitem(REGISTRY, "spy-test", entry)
        obs = SwitchedObserver(system, None, cycles=[Cycle.from_ts(2.0, 0.6)], family="spy-test")
    ctx = seen["args"][0]
    assert isinstance(ctx, FamilyContext) and not any(a is obs for a in seen["args"])
    assert (ctx.n, ctx.N, ctx.p, ctx.hold) == (obs.n, obs.N, obs.p, obs.hold)
    assert ctx.A is obs.A and ctx.B is obs.B and ctx.C is obs.C and ctx.system is system
    assert ctx.zoh(OPEN_LOOP, 0.02) is obs.cache.step(OPEN_LOOP, 0.02)
