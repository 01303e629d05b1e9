"""The launch files (launch/*.launch.py) and the per-robot params template name only what exists.

Everywhere: each launch file is parsed (AST): every ``Node(package=..., executable=...)`` names this
package and one of its console scripts, every params file it names
(``PathJoinSubstitution([FindPackageShare(pkg), "config", "<file>"])``) is in config/ (installed
under share/<pkg>/config), every ``LaunchConfiguration`` is declared, and setup.py installs the
launch files. Where launch_ros is importable (a ROS installation; not the PyPI environment), each
file's launch description is also built and run.
"""

from __future__ import annotations

import ast
import importlib.util
import re
from pathlib import Path

import pytest

from switchobs_ros.config import PARAMS, EstimatorConfig, params_from_file

REPO = Path(__file__).resolve().parents[2]
LAUNCH = sorted((REPO / "launch").glob("*.launch.py"))
PACKAGE = re.search(r"<name>(.*?)</name>", (REPO / "package.xml").read_text()).group(1)


def _console_scripts() -> set[str]:
    tree = ast.parse((REPO / "setup.py").read_text())
    for node in ast.walk(tree):
        if isinstance(node, ast.Dict):
            for k, v in zip(node.keys, node.values):
                if isinstance(k, ast.Constant) and k.value == "console_scripts":
                    return {ast.literal_eval(e).split("=")[0].strip() for e in v.elts}
    raise AssertionError("setup.py has no console_scripts")


def _kw(call: ast.Call, name: str):
    return next((k.value for k in call.keywords if k.arg == name), None)


def _name(call: ast.Call) -> str:
    f = call.func
    return f.id if isinstance(f, ast.Name) else f.attr if isinstance(f, ast.Attribute) else ""


def test_there_are_the_two_launch_files():
    assert [p.name for p in LAUNCH] == ["estimator.launch.py", "estimator_camera_sim.launch.py"]


@pytest.mark.parametrize("path", LAUNCH, ids=lambda p: p.name)
def test_launch_file_names_only_what_exists(path):
    tree = ast.parse(path.read_text())
    calls = [n for n in ast.walk(tree) if isinstance(n, ast.Call)]
    scripts = _console_scripts()
    nodes = [c for c in calls if _name(c) == "Node"]
    assert nodes, "a launch file starts at least one node"
    for c in nodes:
        pkg, exe = ast.literal_eval(_kw(c, "package")), ast.literal_eval(_kw(c, "executable"))
        assert pkg == PACKAGE, pkg
        assert exe in scripts, f"{exe} is not a console script of setup.py ({sorted(scripts)})"
        assert (REPO / "switchobs_ros" / f"{exe}.py").exists() or exe in scripts
    declared = {ast.literal_eval(c.args[0]) for c in calls if _name(c) == "DeclareLaunchArgument"}
    used = {ast.literal_eval(c.args[0]) for c in calls if _name(c) == "LaunchConfiguration"}
    assert used <= declared, f"undeclared launch arguments: {used - declared}"
    files = []
    for c in calls:
        if _name(c) == "PathJoinSubstitution":
            parts = c.args[0].elts
            share = parts[0]
            if isinstance(share, ast.Name):      # share = FindPackageShare(...)
                share = next(a.value for a in ast.walk(tree) if isinstance(a, ast.Assign)
                             and any(isinstance(t, ast.Name) and t.id == share.id for t in a.targets))
            assert _name(share) == "FindPackageShare" and ast.literal_eval(share.args[0]) == PACKAGE
            rel = [ast.literal_eval(p) for p in parts if isinstance(p, ast.Constant)]
            files.append(Path(*rel))
    assert files, "the params files come from the package's share folder"
    for f in files:
        assert f.parts[0] == "config" and (REPO / f).is_file(), f
    # the docstring's files exist too
    for ref in re.findall(r"config/[\w.]+\.yaml", ast.get_docstring(tree)):
        assert (REPO / ref).is_file(), ref


def test_setup_installs_the_launch_files_and_the_config():
    text = (REPO / "setup.py").read_text()
    assert '("share/" + package_name + "/launch", sorted(glob("launch/*.launch.py")))' in text
    assert 'sorted(glob("config/*.yaml"))' in text


def test_robot_template_is_a_valid_commented_params_file():
    path = REPO / "config" / "robot_template.yaml"
    values = params_from_file([path])
    conf = EstimatorConfig.from_values(values)
    assert conf.system.name == "paper" and conf.transforms == {}
    text = path.read_text()
    # a comment on (or just above) every parameter or section it sets
    lines = text.splitlines()
    for i, line in enumerate(lines):
        if re.match(r"^    [a-z_]+:", line):
            assert "#" in line or lines[i - 1].strip().startswith("#"), f"uncommented: {line}"
    known = {p.name.split(".")[0] for p in PARAMS}
    for key in re.findall(r"^    ([a-z_]+):", text, re.M):
        assert key in known, key


@pytest.mark.parametrize("path", LAUNCH, ids=lambda p: p.name)
def test_launch_description_builds_where_launch_ros_is_importable(path):
    pytest.importorskip("launch_ros", reason="launch_ros is not importable here (ROS 2 from PyPI has no launch)")
    spec = importlib.util.spec_from_file_location(path.stem.replace(".", "_"), path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    ld = mod.generate_launch_description()
    assert ld.entities
