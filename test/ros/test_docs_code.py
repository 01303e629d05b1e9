"""Every code block of the documentation (README.md and docs/**/*.md) runs in a test, so no example
can drift from the code.

What "runs" means per language:

- ``python``: executed, each block in a fresh namespace in a temporary folder;
- ``bash``: every command must be ``switchobs ...``, ``switchobs_bag ...`` or
  ``bash scripts/demo.sh|test.sh ...``, and is checked against the command's own argparse parser
  (the flags and their values parse, as ``--help`` documents them); blocks marked
  ``<!-- docs-test: tutorial -->`` are also *run*, in a fresh clone, by test_tutorial_clone.py;
  the numbers the pages print are re-computed by test/core/test_docs_numbers.py;
- ``yaml`` and ``json``: parsed;
- ``text``: output or formulas, shown as is.

A block that is not meant to run (it needs a ROS installation, runs nodes over DDS for
minutes, or is an API sketch) says so on the line before its fence with
``<!-- docs-test: skip: REASON -->``; the reason is required. Any other block fails here.
"""

from __future__ import annotations

import json
import re
import shlex
from pathlib import Path

import pytest
import yaml

REPO = Path(__file__).resolve().parents[2]
FENCE = re.compile(r"^(?P<indent>[ ]*)```(?P<lang>[\w-]*)[^\n]*\n(?P<body>.*?)^(?P=indent)```[ ]*$", re.M | re.S)
MARKER = re.compile(r"^\s*<!-- docs-test: (?P<kind>skip|tutorial)(?::(?P<why>.*?))? -->\s*$")
ANY_MARKER = re.compile(r"<!-- docs-test:")
LANGS = {"python", "bash", "yaml", "json", "text"}


def pages() -> list[Path]:
    return [REPO / "README.md", *sorted((REPO / "docs").rglob("*.md"))]


def blocks() -> list[tuple[str, int, str, str, str, str]]:
    """``(page, line, lang, body, marker kind, reason)`` of every fenced block."""
    out = []
    for page in pages():
        text = page.read_text()
        for m in FENCE.finditer(text):
            line = text.count("\n", 0, m.start()) + 1
            before = text[:m.start()].rstrip("\n").rsplit("\n", 1)[-1]
            mk = MARKER.match(before)
            body = "\n".join(ln[len(m.group("indent")):] for ln in m.group("body").splitlines())
            out.append((str(page.relative_to(REPO)), line, m.group("lang"), body,
                        mk.group("kind") if mk else "", (mk.group("why") or "").strip() if mk else ""))
    return out


def commands(body: str) -> list[list[str]]:
    """The shell commands of a block: continuation lines joined, comments and a trailing ``&``
    dropped."""
    out = []
    for logical in body.replace("\\\n", " ").splitlines():
        words = shlex.split(logical, comments=True)
        if words and words[-1] == "&":
            words = words[:-1]
        if words:
            out.append(words)
    return out


def check_command(words: list[str]) -> None:
    """Parse ``words`` with the parser of its command (argparse exits on a bad flag or value)."""
    if words[0] == "switchobs":
        from switchobs_core.cli import build_parser

        build_parser().parse_args(words[1:])
    elif words[0] == "switchobs_bag":
        from switchobs_ros.bag.cli import build_parser
        from switchobs_ros.bag.cli._common import split_ros_args

        build_parser().parse_args(split_ros_args(words[1:])[0])
    elif words[:2] == ["bash", "scripts/demo.sh"]:
        from tools.demo import build_parser

        build_parser().parse_args(words[2:])
    elif words[:2] == ["bash", "scripts/test.sh"]:
        assert (REPO / "scripts" / "test.sh").is_file()
    else:
        raise AssertionError(f"{' '.join(words)!r} is not a switchobs command this test can check: run it "
                             "elsewhere and mark the block <!-- docs-test: skip: REASON -->")


ALL = blocks()


def _id(b) -> str:
    return f"{b[0]}:{b[1]}"


def test_the_docs_have_blocks_of_every_kind():
    langs = [b[2] for b in ALL]
    assert langs.count("python") >= 10 and langs.count("bash") >= 15 and langs.count("yaml") >= 4
    assert sum(b[4] == "tutorial" for b in ALL) >= 3
    assert sum(b[2] == "python" and not b[4] for b in ALL) >= 6        # executed, not just listed


def test_every_marker_sits_on_a_fence_and_every_skip_says_why():
    for page in pages():
        text = page.read_text()
        for m in ANY_MARKER.finditer(text):
            line = text.count("\n", 0, m.start()) + 1
            rest = text[m.start():].split("\n", 2)
            assert MARKER.match(rest[0]), f"{page.name}:{line}: malformed marker {rest[0]!r}"
            assert len(rest) > 1 and rest[1].lstrip().startswith("```"), f"{page.name}:{line}: no fence after it"
    for b in ALL:
        if b[4] == "skip":
            assert len(b[5]) >= 10, f"{_id(b)}: a skip needs its reason"


@pytest.mark.parametrize("block", ALL, ids=_id)
def test_code_block(block, tmp_path, monkeypatch):
    page, line, lang, body, kind, why = block
    assert lang in LANGS, f"{page}:{line}: give the block one of the languages {sorted(LANGS)}"
    if kind == "skip":
        pytest.skip(why)
    if lang == "python":
        monkeypatch.chdir(tmp_path)
        exec(compile(body, f"{page}:{line}", "exec"), {"__name__": "__docs__"})
    elif lang == "bash":
        cmds = commands(body)
        assert cmds, f"{page}:{line}: an empty shell block"
        for words in cmds:
            try:
                check_command(words)
            except SystemExit as err:
                raise AssertionError(f"{page}:{line}: {' '.join(words)!r} does not parse (exit {err.code})") from None
    elif lang == "yaml":
        assert yaml.safe_load(body) is not None
    elif lang == "json":
        json.loads(body)


def test_a_bad_flag_or_an_unknown_command_fails_the_check():
    """The check can fail: a misspelled flag, a bad value, a command it does not know."""
    for words in (["switchobs", "design", "paper", "--cycel", "2,0.6"], ["switchobs_bag", "report"],
                  ["bash", "scripts/demo.sh", "--duration", "-5"]):
        with pytest.raises(SystemExit):
            check_command(words)
    with pytest.raises(AssertionError, match="mark the block"):
        check_command(["colcon", "build"])
    assert commands("switchobs show a.json \\\n    --system paper   # why\nfoo &\n") == [
        ["switchobs", "show", "a.json", "--system", "paper"], ["foo"]]
