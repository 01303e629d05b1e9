"""Conventions of the whole repository that keep it readable for the next engineer: small modules,
the core's flat top kept short, no issue numbers or history in code, no linear algebra in the ROS
layer (its math lives in ``switchobs_core``), and ``switchobs_core`` free of ROS."""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
#: Where the project's Python lives (the virtualenv and build output are not the project's).
PY_DIRS = ("switchobs_core", "msg_bridge", "switchobs_ros", "tools", "bench", "test", "scripts", "launch")
MAX_LINES = 600
MAX_LOOSE_CORE_MODULES = 15


def _py_files() -> list[Path]:
    return sorted(p for d in PY_DIRS if (REPO / d).is_dir() for p in (REPO / d).rglob("*.py"))


def test_the_scan_sees_the_project():
    files = {p.relative_to(REPO).as_posix() for p in _py_files()}
    assert {"switchobs_core/runtime/observer.py", "switchobs_ros/pipeline.py", "msg_bridge/convert.py"} <= files


def test_no_module_over_600_lines():
    long = [f"{p.relative_to(REPO)}: {n} lines" for p in _py_files()
            if (n := len(p.read_text().splitlines())) > MAX_LINES]
    assert not long, long


def test_test_file_names_are_unique():
    """pytest imports test files by their base name (no packages under test/): two files of one
    name in two folders stop the collection."""
    names = [p.name for p in (REPO / "test").rglob("*.py") if p.name != "conftest.py" and p.name != "__init__.py"]
    assert len(names) == len(set(names)), sorted(n for n in set(names) if names.count(n) > 1)


def test_at_most_15_loose_core_modules():
    loose = sorted(p.name for p in (REPO / "switchobs_core").glob("*.py"))
    assert len(loose) <= MAX_LOOSE_CORE_MODULES, loose


#: "issue 13", "(issue 22)", "Issue 20's", "round 2": history belongs in git, not in the code.
HISTORY = re.compile(r"\b[Ii]ssue\s*#?\d+|\bround\s*2\b|\bround2\b")


def test_no_issue_numbers_or_rounds_in_code_or_test_names():
    hits = [f"{p.relative_to(REPO)}:{i}: {line.strip()[:100]}" for p in _py_files()
            if p.name != "test_repository.py"
            for i, line in enumerate(p.read_text().splitlines(), 1) if HISTORY.search(line)]
    names = [p.name for p in _py_files() if HISTORY.search(p.stem.replace("_", " "))]
    assert not hits and not names, hits + names


def _linear_algebra(tree: ast.AST) -> list[str]:
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.BinOp) and isinstance(node.op, ast.MatMult):
            out.append(f"{node.lineno}: matrix product")
        elif isinstance(node, ast.Attribute) and node.attr == "linalg":
            out.append(f"{node.lineno}: linalg")
        elif isinstance(node, (ast.Import, ast.ImportFrom)):
            mods = [a.name for a in node.names] if isinstance(node, ast.Import) else [node.module or ""]
            out += [f"{node.lineno}: import {m}" for m in mods if m.split(".")[0] == "scipy"]
        elif isinstance(node, ast.Call) and getattr(node.func, "attr", "") in ("dot", "solve", "inv", "eigh",
                                                                             "eigvalsh", "cholesky", "norm"):
            out.append(f"{node.lineno}: {node.func.attr}()")
    return out


@pytest.mark.parametrize("package", ["switchobs_ros", "msg_bridge"])
def test_no_linear_algebra_outside_the_core(package):
    """The ROS layer and the bridge hold no math: products, solves, norms and eigenvalues are the
    core's (one owner per formula); they call it with plain arrays."""
    found = [f"{p.relative_to(REPO)}:{hit}" for p in sorted((REPO / package).rglob("*.py"))
             for hit in _linear_algebra(ast.parse(p.read_text()))]
    assert not found, found


def test_linear_algebra_scan_catches_a_product():
    assert _linear_algebra(ast.parse("import numpy as np\nx = a @ b\ny = np.linalg.norm(x)\n"))


def test_the_core_never_imports_ros():
    ros = ("rclpy", "msg_bridge", "switchobs_ros", "std_msgs", "geometry_msgs", "nav_msgs", "sensor_msgs",
           "diagnostic_msgs", "builtin_interfaces", "switchobs_msgs", "rosbags")
    bad = []
    for p in sorted((REPO / "switchobs_core").rglob("*.py")):
        for node in ast.walk(ast.parse(p.read_text())):
            if isinstance(node, (ast.Import, ast.ImportFrom)):
                mods = [a.name for a in node.names] if isinstance(node, ast.Import) else [node.module or ""]
                bad += [f"{p.relative_to(REPO)}:{node.lineno} {m}" for m in mods if m.split(".")[0] in ros]
    assert not bad, bad
