"""Every ``<!-- docs-check ... -->`` block of the documentation pages (docs/**/*.md): its
``switchobs`` commands run in-process, the last one with ``--json``, and each
``expect PATH = VALUE`` holds to the precision the page prints VALUE with (and VALUE is printed
in that page's text)."""

from __future__ import annotations

import json
import re
import shlex
from pathlib import Path

import pytest

from switchobs_core.cli import main

DOCS = Path(__file__).resolve().parents[2] / "docs"
_BLOCK = re.compile(r"<!-- docs-check\n(.*?)-->", re.S)


def _blocks() -> list[tuple[Path, str]]:
    return [(p, b) for p in sorted(DOCS.rglob("*.md")) for b in _BLOCK.findall(p.read_text())]


def _lookup(obj, path: str):
    for key in path.split("."):
        obj = obj[int(key)] if isinstance(obj, list) else obj[key]
    return obj


def test_docs_have_check_blocks():
    pages = {p.name for p, _ in _blocks()}
    assert len(_blocks()) >= 6 and {"paper.md", "plan.md"} <= pages


@pytest.mark.parametrize("page,block", _blocks(),
                         ids=lambda x: x.name if isinstance(x, Path) else x.strip().split("\n")[0][:60])
def test_docs_block(page, block, tmp_path, capsys):
    prose = _BLOCK.sub("", page.read_text())
    lines = [ln.strip() for ln in block.strip().splitlines() if ln.strip()]
    cmds = [ln for ln in lines if ln.startswith("switchobs ")]
    expects = [ln[len("expect "):] for ln in lines if ln.startswith("expect ")]
    assert cmds and expects, block
    for cmd in cmds:
        capsys.readouterr()
        args = shlex.split(cmd.replace("{tmp}", str(tmp_path)))[1:]
        if args[0] == "design":
            args.append("--no-progress")
        assert main(args) == 0, cmd
    out = json.loads(capsys.readouterr().out)
    for e in expects:
        path, value = (x.strip() for x in e.split("="))
        decimals = len(value.split(".")[1]) if "." in value else 0
        got = float(_lookup(out, path))
        assert abs(got - float(value)) <= 0.5 * 10.0**-decimals + 1e-12, (path, got, value)
        assert re.search(rf"(?<![\d.]){re.escape(value)}(?![\d])", prose), f"{value} is not printed in {page.name}"
