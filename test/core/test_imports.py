"""Import structure of switchobs_core: every module imports on its own, project-internal
imports sit at module top (lazy only for heavy optional dependencies), no import cycle."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import switchobs_core

PKG = Path(switchobs_core.__file__).parent
#: Imports allowed inside functions: heavy or optional third-party dependencies (a package, or a
#: subpackage named in full: scipy's optimisers and interpolants, which only a design needs, cost an
#: estimator that loads a cached table a tenth of a second of start-up).
LAZY_OK = {"cvxpy", "matplotlib", "tqdm", "threadpoolctl", "yaml", "scipy.optimize", "scipy.interpolate"}
#: Modules whose function is an import made under conditions it sets first (and so inside a function):
#: ``lean_scipy`` imports scipy with numpy's star-export trimmed, and scipy's docstring parser at its
#: first use after that import. The chi-square gate imports ``scipy.special`` (its quantile) when it is
#: made with a false-alarm rate > 0: an estimator start without the gate (the default) does not.
#: The gain families design a table only when none is given: the design stack (the SDP solver's modules,
#: the Riccati doubling) is imported by the start that designs, not by every start that loads a table.
LAZY_BY_PURPOSE = {"switchobs_core.lean_scipy": {"scipy.linalg", "scipy.sparse", "scipy._lib._docscrape"},
                   "switchobs_core.runtime.gate": {"scipy.special"},
                   "switchobs_core.runtime.families.lmi": {"switchobs_core.design.lmi"},
                   "switchobs_core.runtime.families.kalman": {"switchobs_core.design.kalman"}}


def _modules() -> dict[str, Path]:
    out = {}
    for p in sorted(PKG.rglob("*.py")):
        parts = list(p.relative_to(PKG.parent).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts.pop()
        if parts[-1] != "__main__":     # runs the command line
            out[".".join(parts)] = p
    return out


def _target(mod: str, is_pkg: bool, node: ast.ImportFrom | ast.Import) -> list[str]:
    """Absolute names a node imports (for ``from . import x``, also ``pkg.x``)."""
    if isinstance(node, ast.Import):
        return [a.name for a in node.names]
    base = mod.split(".") if is_pkg else mod.split(".")[:-1]
    if node.level:
        base = base[: len(base) - (node.level - 1)]
        name = ".".join(base + ([node.module] if node.module else []))
    else:
        name = node.module or ""
    return [name] + [f"{name}.{a.name}" for a in node.names]


def _is_type_checking(node: ast.If) -> bool:
    t = node.test
    return (isinstance(t, ast.Name) and t.id == "TYPE_CHECKING") or (
        isinstance(t, ast.Attribute) and t.attr == "TYPE_CHECKING")


def _scan(mod: str, path: Path) -> tuple[set[str], list[str]]:
    """(project modules imported at run time at module level, imports inside functions)."""
    tree = ast.parse(path.read_text())
    is_pkg = path.name == "__init__.py"
    top: set[str] = set()
    lazy: list[str] = []

    def visit(node: ast.AST, in_func: bool) -> None:
        for child in ast.iter_child_nodes(node):
            if isinstance(child, ast.If) and _is_type_checking(child):
                continue
            f = in_func or isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda))
            if isinstance(child, (ast.Import, ast.ImportFrom)):
                names = _target(mod, is_pkg, child)
                if f and names[0].split(".")[0] not in LAZY_OK and names[0] not in LAZY_OK \
                        and names[0] not in LAZY_BY_PURPOSE.get(mod, ()):
                    lazy.append(f"{mod}:{child.lineno} {names[0]}")
                elif not f:
                    top.update(n for n in names if n.split(".")[0] == "switchobs_core")
            visit(child, f)

    visit(tree, False)
    return top, lazy


def test_every_module_imports_in_a_fresh_interpreter():
    mods = sorted(_modules())
    code = f"import importlib\nfor m in {mods!r}:\n    importlib.import_module(m)\n"
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert res.returncode == 0, res.stderr


def test_no_import_inside_functions_except_heavy_optional_deps():
    lazy = [x for m, p in _modules().items() for x in _scan(m, p)[1]]
    assert not lazy, lazy


def test_module_import_graph_has_no_cycle():
    mods = _modules()
    graph = {}
    for m, p in mods.items():
        deps = {d for d in _scan(m, p)[0] if d in mods and d != m}
        # importing a.b.c runs the packages a.b's __init__ too (not a cycle of m's own making)
        graph[m] = {d for d in deps if not m.startswith(d + ".")}
    state: dict[str, int] = {}
    path: list[str] = []

    def dfs(u: str) -> None:
        state[u] = 1
        path.append(u)
        for v in sorted(graph[u]):
            if state.get(v) == 1:
                raise AssertionError("import cycle: " + " -> ".join(path[path.index(v):] + [v]))
            if v not in state:
                dfs(v)
        path.pop()
        state[u] = 2

    for m in sorted(graph):
        if m not in state:
            dfs(m)
    obs = "switchobs_core.runtime.observer"
    assert obs in graph and graph[obs]   # the scan sees imports


#: The layers, lowest first (docs/architecture.md): a module imports only from its own layer and
#: lower ones. Loose modules (exceptions, validation, ranges, files, loading, paper, threads, the
#: registry families) are the base; a subpackage is its own layer; the package itself (its
#: ``__init__`` re-exports everything) is above them all.
LAYERS = ("base", "numerics", "model", "bounds", "certificate", "table", "design", "runtime", "sim", "cli",
          "package")
#: Modules that import by a computed name (not checked statically), and why that is no layer's business.
COMPUTED_IMPORTS = {
    "switchobs_core.families": "the registry: each entry names its runtime type, imported on first use by "
                               "the caller (the observer, the simulator, the command line)",
    "switchobs_core.cli": "its subcommands, modules of its own layer",
}


def _layer(mod: str) -> str:
    parts = mod.split(".")
    if len(parts) == 1:
        return "package"
    return parts[1] if parts[1] in LAYERS else "base"


def _imports_anywhere(mod: str, path: Path, mods: dict[str, Path]) -> tuple[list[tuple[int, str]], list[int]]:
    """Every project module ``mod`` imports, wherever the import sits (module level, inside a function,
    under ``TYPE_CHECKING``, or ``importlib.import_module`` of a constant name): ``(line, module)``;
    and the lines of ``import_module`` calls with a computed name."""
    tree = ast.parse(path.read_text())
    is_pkg = path.name == "__init__.py"
    out: list[tuple[int, str]] = []
    computed: list[int] = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out += [(node.lineno, a.name) for a in node.names if a.name.split(".")[0] == "switchobs_core"]
        elif isinstance(node, ast.ImportFrom):
            base, *names = _target(mod, is_pkg, node)
            if base.split(".")[0] != "switchobs_core":
                continue
            # `from pkg import sub` imports the module pkg.sub; `from mod import name`, mod itself
            out += [(node.lineno, n if n in mods else base) for n in names]
        elif isinstance(node, ast.Call) and getattr(node.func, "attr", getattr(node.func, "id", "")) == "import_module":
            arg = node.args[0] if node.args else None
            if isinstance(arg, ast.Constant) and isinstance(arg.value, str):
                if arg.value.split(".")[0] == "switchobs_core":
                    out.append((node.lineno, arg.value))
            else:
                computed.append(node.lineno)
    return out, computed


def test_no_module_imports_a_higher_layer():
    mods = {m: p for m, p in _modules().items() if m != "switchobs_core"}
    assert {_layer(m) for m in mods} == set(LAYERS) - {"package"}, "a layer without modules, or a new subpackage"
    up, computed = [], []
    for m, p in sorted(mods.items()):
        found, lines = _imports_anywhere(m, p, mods)
        up += [f"{m} ({_layer(m)}):{line} imports {t} ({_layer(t)})" for line, t in found
               if LAYERS.index(_layer(t)) > LAYERS.index(_layer(m))]
        computed += [f"{m}:{line}" for line in lines if m not in COMPUTED_IMPORTS]
    assert not up, "\n".join(up)
    assert not computed, computed
    # the scan sees imports: the observer imports the envelopes and the gain table's Kalman design
    found = {t for _, t in _imports_anywhere("switchobs_core.runtime.observer", mods["switchobs_core.runtime.observer"],
                                             mods)[0]}
    assert {"switchobs_core.bounds.envelope", "switchobs_core.table.kalman"} <= found
