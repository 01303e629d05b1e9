"""The generated pages of the documentation site (``mkdocs.yml``; :mod:`tools.docs_hooks` adds them
to the build, the tests read them from here).

Each page is rendered from the one owner of what it documents, never copied:

- :func:`cli_reference`: the ``switchobs``, ``switchobs_bag`` and demo argparse parsers
  (``switchobs_core.cli.build_parser``, ``switchobs_ros.bag.cli.build_parser``,
  ``tools.demo.build_parser``), one section per subcommand with its usage and a table of its
  arguments;
- :func:`parameters_reference`: the nodes' parameter tables (``switchobs_ros.config.PARAMS``,
  ``switchobs_ros.camera_sim.PARAMS``) and which of them may change while the node runs
  (``switchobs_ros.config.RUNTIME_PARAMS``);
- :func:`api_modules` / :func:`api_pages`: one page per module of the three packages, found on disk
  (a module added later gets its page without editing the docs), rendered by mkdocstrings from the
  docstrings;
- :func:`benchmarks_page`: ``bench/RESULTS.md`` as a page of the site.
"""

from __future__ import annotations

import argparse
import json
import re
from pathlib import Path

__all__ = ["API_PACKAGES", "GENERATED", "PUBLIC_API", "api_modules", "api_nav", "api_pages", "benchmarks_page",
           "cli_reference", "copied_files", "generated_pages", "parameters_reference", "strip_roles"]

ROOT = Path(__file__).resolve().parents[1]
#: The packages whose modules get an API page (``reference/api/<module>.md``).
API_PACKAGES = ("switchobs_core", "msg_bridge", "switchobs_ros")
#: Pages made by :func:`generated_pages` that are not per-module API pages.
GENERATED = ("reference/cli.md", "reference/parameters.md", "reference/benchmarks.md", "reference/api/index.md")


def _cell(text: str) -> str:
    """Text for one Markdown table cell: one line, pipes escaped."""
    return " ".join(str(text).split()).replace("|", "\\|")


def _help(action: argparse.Action) -> str:
    text = action.help or ""
    if "%(" in text:
        try:
            text = text % {"default": action.default, "prog": "", "choices": action.choices}
        except (KeyError, TypeError, ValueError):
            pass
    return text


def _arguments_table(parser: argparse.ArgumentParser) -> list[str]:
    rows = ["| argument | default | meaning |", "|---|---|---|"]
    for a in parser._actions:
        if isinstance(a, (argparse._HelpAction, argparse._SubParsersAction)) or a.help == argparse.SUPPRESS:
            continue
        if a.option_strings:
            meta = "" if a.nargs == 0 else " " + (a.metavar or a.dest.upper()) if not a.choices else \
                " {" + ",".join(map(str, a.choices)) + "}"
            name = ", ".join(f"`{o}{meta if o == a.option_strings[-1] else ''}`" for o in a.option_strings)
        else:
            name = f"`{a.metavar or a.dest}`" + (" (one of " + ", ".join(f"`{c}`" for c in a.choices) + ")"
                                                 if a.choices else "")
        hidden = a.default is None or a.default is False or a.default is argparse.SUPPRESS or a.nargs == 0 \
            or a.required or not a.option_strings
        default = "" if hidden else '`""`' if a.default == "" else f"`{a.default}`"
        if a.required and a.option_strings:
            default = "required"
        rows.append(f"| {name} | {default} | {_cell(_help(a))} |")
    return rows


def _subparsers(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    for a in parser._actions:
        if isinstance(a, argparse._SubParsersAction):
            return dict(a.choices)
    return {}


def _command_section(prog: str, parser: argparse.ArgumentParser, intro: str) -> list[str]:
    out = [f"## `{prog}`", "", intro, ""]
    for name, sub in _subparsers(parser).items():
        out += [f"### `{prog} {name}`", "", _cell(sub.description or ""), "", "```text",
                sub.format_usage().strip().removeprefix("usage: "), "```", ""]
        out += _arguments_table(sub) + [""]
    return out


def cli_reference() -> str:
    """The command-line reference, from the argparse parsers themselves."""
    from switchobs_core.cli import build_parser as core_parser
    from switchobs_ros.bag.cli import build_parser as bag_parser

    out = ["# Command-line reference", "",
           "Generated from the argparse parsers at every build of this site, so it cannot drift from "
           "the commands. Every command takes `--help`. An error is one line on stderr "
           "(`switchobs CMD: error: ...`, `switchobs_bag: error: ...`) and exit code 2; see "
           "[Troubleshooting](../troubleshooting.md).", ""]
    out += _command_section("switchobs", core_parser(),
                            "Offline design, inspection, the paper's reproduction, simulation, certificates and "
                            "schedule planning (`switchobs_core`, no ROS).")
    out += _command_section("switchobs_bag", bag_parser(),
                            "rosbag2 bags through the estimator, live and offline "
                            "([Bags](../tutorials/node-and-bags.md)). "
                            "Arguments after `--ros-args` go to the node of `record` and `play`.")
    from tools.demo import build_parser as demo_parser

    demo = demo_parser()
    out += ["## `bash scripts/demo.sh`", "",
            "The demo ([Getting started](../getting-started.md)): " + _cell(demo.description or ""), "",
            "```text", demo.format_usage().strip().removeprefix("usage: "), "```", ""]
    out += _arguments_table(demo) + [""]
    return "\n".join(out) + "\n"


def _default(value) -> str:
    if isinstance(value, tuple):
        value = list(value)
    return f"`{json.dumps(value)}`"


def parameters_reference() -> str:
    """The nodes' parameters, from their declared tables."""
    from switchobs_ros import camera_sim, config

    out = ["# Node parameters", "",
           "Generated from the parameter tables the nodes declare (`switchobs_ros.config.PARAMS`, "
           "`switchobs_ros.camera_sim.PARAMS`) at every build of this site. A params file is "
           "`<node key>: ros__parameters: {...}` with nested keys joined by `.`; `config/estimator.yaml` and "
           "`config/camera_sim.yaml` list every parameter with its default, keyed `/**` (any node, in any "
           "namespace: one file for every robot of a fleet). An unknown name, a value of the wrong type, or "
           "a params file with no section for the node (`estimator:` under `/robot1`) stops start-up with "
           "one line and exit code 2 "
           "([Troubleshooting](../troubleshooting.md)).", ""]
    for title, params, runtime in (("estimator", config.PARAMS, config.RUNTIME_PARAMS),
                                   ("camera_sim", camera_sim.PARAMS, {})):
        out += [f"## `{title}`", ""]
        if runtime:
            out += ["Parameters marked *runtime* can change while the node runs (`ros2 param set`, the "
                    "`set_parameters` service); any other is refused with the reason, and a name the node does "
                    "not declare gets `unknown parameter NAME (known: ...)`.", ""]
        # two columns: the name (never broken: stylesheets/tables.css) with its type, default and whether it
        # is a runtime parameter under it; the meaning takes the rest of the width
        out += ["| parameter | meaning |", "|---|---|"]
        for p in params:
            rt = " · *runtime*" if p.name in runtime else ""
            out.append(f"| `{p.name}`<br>{p.type_name} · default {_default(p.default)}{rt} | {_cell(p.description)} |")
        out.append("")
    return "\n".join(out) + "\n"


def api_modules() -> list[str]:
    """Dotted names of the documented modules: every ``.py`` file of :data:`API_PACKAGES` whose
    name does not start with ``_`` (packages by their ``__init__``), in path order."""
    mods = []
    for pkg in API_PACKAGES:
        for path in sorted((ROOT / pkg).rglob("*.py")):
            rel = path.relative_to(ROOT).with_suffix("")
            parts = list(rel.parts)
            if parts[-1] == "__init__":
                parts = parts[:-1]
            if any(p.startswith("_") for p in parts):
                continue
            mods.append(".".join(parts))
    return mods


def _is_package(mod: str) -> bool:
    return (ROOT / mod.replace(".", "/") / "__init__.py").is_file()


#: The public API, first in the navigation and the index (in this order); every other module is
#: listed after them, under its package (collapsed in the navigation).
PUBLIC_API = (
    "switchobs_core",                       # re-exports every public name (import switchobs_core as so)
    "switchobs_core.runtime.observer",      # SwitchedObserver: update, hold_input, envelope
    "switchobs_core.model.system",          # LTISystem
    "switchobs_core.model.schedule",        # Cycle, schedules
    "switchobs_core.table.gains",           # GainTable: save, load
    "switchobs_core.design.lmi",            # the paper's LMI design
    "switchobs_core.design.kalman",         # offline periodic Kalman design
    "switchobs_core.sim.simulate",          # simulate
    "msg_bridge",                           # messages <-> numpy
    "msg_bridge.typed",                     # StateEstimate, ErrorBounds
    "switchobs_ros.pipeline",               # EstimatorPipeline: the node's input handling, offline too
    "switchobs_ros.bag.estimate",           # switchobs_bag estimate from Python
)


def _summary(mod: str) -> str:
    """The first line of a module's docstring (read from the file, nothing imported)."""
    import ast

    path = ROOT / mod.replace(".", "/")
    path = path / "__init__.py" if path.is_dir() else path.with_suffix(".py")
    try:
        doc = ast.get_docstring(ast.parse(path.read_text())) or ""
    except (OSError, SyntaxError):
        return ""
    line = doc.strip().split("\n\n", 1)[0].replace("\n", " ")
    return _cell(re.sub(r":(?:mod|class|func|meth|attr|data|exc|obj):`~?([^`]+)`", r"`\1`", line))


def api_nav() -> list:
    """The navigation of the Python API: the overview, the public API, then every module under its
    package (collapsed: a section per package)."""
    mods = api_modules()
    public = [m for m in PUBLIC_API if m in mods]
    nav: list = [{"Overview": "reference/api/index.md"},
                 {"Public API": [{m: f"reference/api/{m}.md"} for m in public]}]
    nav.append({"All modules": [{pkg: [{m: f"reference/api/{m}.md"} for m in mods
                                       if m == pkg or m.startswith(pkg + ".")]} for pkg in API_PACKAGES]})
    return nav


def api_pages() -> dict[str, str]:
    """``{path under docs/: Markdown}`` of the API reference: an index and one page per module."""
    mods = api_modules()
    pages = {}
    index = ["# Python API", "",
             "One page per module, rendered from the docstrings (numpydoc) at every build; the list is "
             "made from the packages' files, so a new module appears here by itself. `switchobs_core` is "
             "ROS-free; `msg_bridge` converts messages; `switchobs_ros` holds the nodes and tools. "
             "The [API overview](../../api.md) shows the calls in use.", "",
             "## Public API", "",
             "What an application imports; `import switchobs_core as so` gives every public name of the core.", ""]
    index += [f"- [`{m}`]({m}.md): {_summary(m)}" for m in PUBLIC_API if m in mods]
    index += ["", "## All modules", "", "Every module, by package: the internals the public API is built from.", ""]
    for pkg in API_PACKAGES:
        index += [f"### `{pkg}`", ""]
        for m in mods:
            if m == pkg or m.startswith(pkg + "."):
                index.append(f"- [`{m}`]({m}.md)")
        index.append("")
    pages["reference/api/index.md"] = "\n".join(index)
    for m in mods:
        opts = "\n    options:\n      members: false" if _is_package(m) else ""
        subs = [s for s in mods if s.startswith(m + ".") and "." not in s[len(m) + 1:]] if _is_package(m) else []
        tail = ("\n\nModules: " + ", ".join(f"[`{s}`]({s}.md)" for s in subs)) if subs else ""
        pages[f"reference/api/{m}.md"] = f"# `{m}`\n\n::: {m}{opts}{tail}\n"
    return pages


#: Sphinx roles in docstrings (``:mod:`x```, ``:class:`~a.B```): the site shows their target as code.
ROLE = re.compile(r":(?:mod|class|func|meth|attr|data|exc|obj|ref):(<code>)~?")


#: A role left as text (inside a code span or an attribute): ``:class:`X``` -> ``X``.
ROLE_TEXT = re.compile(r":(?:mod|class|func|meth|attr|data|exc|obj|ref):`~?([^`<>]*)`")


def strip_roles(html: str) -> str:
    """A rendered page with the reST roles of its docstrings dropped (``:mod:<code>x</code>`` -> ``<code>x</code>``)."""
    return ROLE_TEXT.sub(r"\1", ROLE.sub(r"\1", html))


def benchmarks_page() -> str:
    """``bench/RESULTS.md`` as a page (links into the repository become code spans)."""
    return (ROOT / "bench" / "RESULTS.md").read_text().replace("](figures/", "](../bench-figures/")


def copied_files() -> dict[str, Path]:
    """Files the site shows from outside ``docs/``: ``{path under docs/: source}``."""
    return {f"bench-figures/{p.name}": p for p in sorted((ROOT / "bench" / "figures").glob("*.png"))}


def generated_pages() -> dict[str, str]:
    """Every generated page, ``{path under docs/: Markdown}``."""
    pages = {"reference/cli.md": cli_reference(), "reference/parameters.md": parameters_reference(),
             "reference/benchmarks.md": benchmarks_page()}
    pages.update(api_pages())
    return pages
