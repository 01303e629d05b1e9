"""The documentation site: it builds in strict mode (a broken link, anchor or reference fails);
its generated reference pages (tools/docs_gen.py) document every parameter, command, option and
module from their one owner; README.md stays a short entry point (at most 12 KB) whose links
lead into the site."""

from __future__ import annotations

import re
import subprocess
import sys
import time
from pathlib import Path

import pytest
import yaml

from switchobs_ros import camera_sim, config
from tools import docs_gen

REPO = Path(__file__).resolve().parents[2]


def test_site_builds_in_strict_mode(tmp_path):
    """``mkdocs build --strict`` exits 0 (CI runs it through this test)."""
    t0 = time.monotonic()
    r = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "-q", "-d", str(tmp_path / "site")],
                       cwd=REPO, capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stdout + r.stderr
    site = tmp_path / "site"
    for page in ("index.html", "reference/cli/index.html", "reference/parameters/index.html",
                 "reference/api/switchobs_core.design.synthesis/index.html", "troubleshooting/index.html"):
        assert (site / page).is_file(), page
    # the API pages are rendered from the docstrings, not left as mkdocstrings directives
    html = (site / "reference/api/switchobs_core.design.synthesis/index.html").read_text()
    assert "LMISynthesizer" in html and ":::" not in html
    # the docstrings' reST roles (:mod:`x`) are shown as code, not as raw text
    for mod in ("switchobs_core", "msg_bridge", "switchobs_core.runtime.observer"):
        page = (site / f"reference/api/{mod}/index.html").read_text()
        assert not re.search(r":(mod|class|func|meth|attr|data):[`<]", page), mod
    # the reference tables' names are not broken mid-word (the stylesheet is on every page)
    params = (site / "reference/parameters/index.html").read_text()
    assert "stylesheets/tables.css" in params
    assert "white-space: nowrap" in (site / "stylesheets" / "tables.css").read_text()
    print(f"mkdocs build --strict: {time.monotonic() - t0:.1f} s wall")   # information, not asserted


def test_a_broken_link_fails_the_strict_build(tmp_path):
    """The strict build can fail: the same site with one page linking to a missing page."""
    docs = tmp_path / "docs"
    subprocess.run(["cp", "-r", str(REPO / "docs"), str(docs)], check=True)
    (docs / "troubleshooting.md").write_text((docs / "troubleshooting.md").read_text()
                                             + "\n[gone](no-such-page.md)\n")
    cfg = yaml.safe_load((REPO / "mkdocs.yml").read_text())
    cfg.update(docs_dir=str(docs), site_dir=str(tmp_path / "site"), hooks=[str(REPO / "tools" / "docs_hooks.py")])
    cfg["plugins"] = ["search"]                     # the API pages are not needed to see the link fail
    cfg["nav"] = [x for x in cfg["nav"] if "Reference" not in x]
    (tmp_path / "mkdocs.yml").write_text(yaml.safe_dump(cfg))
    r = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "-f", str(tmp_path / "mkdocs.yml")],
                       cwd=REPO, capture_output=True, text=True, timeout=600)
    assert r.returncode != 0 and "no-such-page.md" in r.stdout + r.stderr


@pytest.mark.parametrize("node,params,runtime", [("estimator", config.PARAMS, config.RUNTIME_PARAMS),
                                                 ("camera_sim", camera_sim.PARAMS, {})])
def test_parameter_reference_lists_every_parameter_with_its_default(node, params, runtime):
    page = docs_gen.parameters_reference().split(f"## `{node}`", 1)[1].split("\n## ", 1)[0]
    for p in params:
        default = list(p.default) if isinstance(p.default, tuple) else p.default
        row = next((ln for ln in page.splitlines() if ln.startswith(f"| `{p.name}`<br>{p.type_name} · default ")),
                   None)
        assert row is not None, p.name
        shown = row.split(" · default ", 1)[1].split(" · ")[0].split(" | ")[0]
        assert yaml.safe_load(shown.strip().strip("`")) == default, (p.name, row)
        assert (" · *runtime* |" in row) == (p.name in runtime), row


@pytest.mark.parametrize("mod,cfg", [(config, "estimator.yaml"), (camera_sim, "camera_sim.yaml")])
def test_default_params_file_lists_every_parameter(mod, cfg):
    data = yaml.safe_load((REPO / "config" / cfg).read_text())["/**"]["ros__parameters"]

    def flat(d, prefix=""):
        for k, v in d.items():
            if isinstance(v, dict):
                yield from flat(v, f"{prefix}{k}.")
            else:
                yield f"{prefix}{k}"
    assert set(flat(data)) == {p.name for p in mod.PARAMS}


def test_cli_reference_lists_every_command_and_option():
    from switchobs_core.cli import build_parser as core
    from switchobs_ros.bag.cli import build_parser as bag
    from tools.demo import build_parser as demo

    page = docs_gen.cli_reference()
    for prog, parser in (("switchobs", core()), ("switchobs_bag", bag())):
        subs = docs_gen._subparsers(parser)
        assert len(subs) >= 6
        for name, sub in subs.items():
            section = page.split(f"### `{prog} {name}`", 1)[1].split("\n### ", 1)[0].split("\n## ", 1)[0]
            for a in sub._actions:
                for opt in a.option_strings:
                    if opt not in ("-h", "--help"):
                        assert f"`{opt}" in section, (prog, name, opt)
    demo_section = page.split("## `bash scripts/demo.sh`", 1)[1]
    assert all(f"`{o}" in demo_section for a in demo()._actions for o in a.option_strings
               if o not in ("-h", "--help"))


def test_api_pages_come_from_the_files_so_new_modules_appear(tmp_path, monkeypatch):
    mods = docs_gen.api_modules()
    on_disk = {".".join(p.relative_to(REPO).with_suffix("").parts)
               for pkg in docs_gen.API_PACKAGES for p in (REPO / pkg).rglob("*.py")
               if not any(x.startswith("_") for x in p.relative_to(REPO).with_suffix("").parts)}
    assert on_disk <= set(mods) and "switchobs_core.design.synthesis" in mods and "msg_bridge.typed" in mods
    assert not any(m.split(".")[-1].startswith("_") for m in mods)
    # a module added later gets its page without editing the docs
    for pkg in docs_gen.API_PACKAGES:
        (tmp_path / pkg).mkdir()
        (tmp_path / pkg / "__init__.py").write_text('"""p."""\n')
    (tmp_path / "switchobs_core" / "brand_new.py").write_text('"""A new module."""\n')
    monkeypatch.setattr(docs_gen, "ROOT", tmp_path)
    pages = docs_gen.api_pages()
    assert "reference/api/switchobs_core.brand_new.md" in pages
    assert "::: switchobs_core.brand_new" in pages["reference/api/switchobs_core.brand_new.md"]
    assert "(switchobs_core.brand_new.md)" in pages["reference/api/index.md"]


def test_readme_is_short_and_its_links_lead_into_the_site():
    readme = (REPO / "README.md").read_text()
    assert len(readme.encode()) <= 12 * 1024
    assert readme.count("```bash") == 1 and "bash scripts/demo.sh" in readme and "bash scripts/test.sh" in readme
    links = re.findall(r"\]\(([^)#]+)(?:#[^)]*)?\)", readme)
    assert len(links) >= 15
    for link in links:
        assert (REPO / link).exists(), link
        assert link.startswith("docs/"), link


def test_api_navigation_puts_the_public_api_first_and_every_module_after_it():
    nav = docs_gen.api_nav()
    assert [next(iter(item)) for item in nav] == ["Overview", "Public API", "All modules"]
    public = [next(iter(e)) for e in nav[1]["Public API"]]
    assert public == list(docs_gen.PUBLIC_API) and public[0] == "switchobs_core"
    sections = nav[2]["All modules"]
    assert [next(iter(sec)) for sec in sections] == list(docs_gen.API_PACKAGES)
    listed = [next(iter(e)) for sec in sections for e in next(iter(sec.values()))]
    assert sorted(listed) == sorted(docs_gen.api_modules()) and len(listed) > 90
    index = docs_gen.api_pages()["reference/api/index.md"]
    assert index.index("## Public API") < index.index("## All modules")
    assert "- [`switchobs_core.runtime.observer`](switchobs_core.runtime.observer.md): The online switched" in index
    assert docs_gen.strip_roles("see :mod:<code>x.y</code> and :class:`~a.B` here") \
        == "see <code>x.y</code> and a.B here"


def test_every_failure_catalogue_row_names_a_test_that_exists():
    """Each row of docs/failures.md's tables names, in its last column, at least one test, and every
    test it names (``file.py::test_name``, ``::test_name`` for the file named before it) is a test
    function of that file."""
    tests: dict[str, set[str]] = {}
    for p in (REPO / "test").rglob("test_*.py"):
        tests.setdefault(p.name, set()).update(re.findall(r"^def (test_\w+)", p.read_text(), re.M))
    rows = 0
    for line in (REPO / "docs" / "failures.md").read_text().splitlines():
        if not line.startswith("|") or set(line) <= set("|-: "):
            continue
        cells = [c.strip() for c in re.split(r"(?<!\\)\|", line.strip().strip("|"))]
        if cells[-1] == "test":          # a header
            continue
        rows += 1
        named = re.findall(r"(test_\w+\.py)(?:::(test_\w+))?|::(test_\w+)", cells[-1])
        assert named, f"no test named: {cells[0][:80]}"
        current = None
        for file, fn, fn_after in named:
            current = file or current
            assert current in tests, f"{cells[0][:60]}: no test file {current}"
            assert (fn or fn_after) in (tests[current] | {""}), f"{cells[0][:60]}: no {current}::{fn or fn_after}"
    assert rows > 80
