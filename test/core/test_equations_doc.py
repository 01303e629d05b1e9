"""Every paper label cited in the repository's code and docs resolves in docs/equations.md,
and the docs name no file outside the repository."""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
EXTS = {".py", ".md", ".yaml", ".yml", ".rst", ".txt", ".toml", ".cfg", ".xml", ".sh"}
SKIP = {".git", ".venv", "build", "install", "log", "__pycache__", ".hypothesis", ".pytest_cache", "node_modules"}
#: A LaTeX label as cited: ``e:tau_k``, ``t:observer-sdp-design``, ``subsec:sim_gain``, ``Sec_Sim``
#: (not a format spec such as ``{t:g}``, not a matplotlib colour such as ``tab:blue``).
LABEL = re.compile(r"(?<![\w./:{-])((?:e|t|s|T|d|def|subsec|sec|l|f|fig|Sec):[A-Za-z][A-Za-z0-9_-]*[A-Za-z0-9_]"
                   r"|Sec_[A-Za-z][A-Za-z0-9_]*)(?![\w}])")
RANGE = re.compile(r"^(.*_)(\d+)-(\d+)$")      # e:SDP_1-4 cites e:SDP_1 .. e:SDP_4


def _files():
    for p in ROOT.rglob("*"):
        if p.is_file() and p.suffix in EXTS and not SKIP.intersection(p.relative_to(ROOT).parts):
            yield p


def _documented() -> set[str]:
    text = (ROOT / "docs" / "equations.md").read_text()
    return set(re.findall(r"^\| `([^`]+)` \|", text, re.M))


def _cited() -> dict[str, str]:
    out: dict[str, str] = {}
    for p in _files():
        if p.name == "equations.md":
            continue
        for m in LABEL.finditer(p.read_text(errors="replace")):
            lab = m.group(1)
            r = RANGE.match(lab)
            labs = [f"{r.group(1)}{i}" for i in range(int(r.group(2)), int(r.group(3)) + 1)] if r else [lab]
            for x in labs:
                out.setdefault(x, str(p.relative_to(ROOT)))
    return out


def test_every_cited_label_is_in_equations_doc():
    doc = _documented()
    cited = _cited()
    assert len(cited) > 20 and "e:tau_k" in cited          # the scan sees the code's citations
    missing = {lab: where for lab, where in cited.items() if lab not in doc}
    assert not missing, f"labels cited but not in docs/equations.md: {missing}"


def test_equations_doc_gives_a_number_for_each_label():
    rows = re.findall(r"^\| `([^`]+)` \| ([^|]+) \| ([^|]*) \|$", (ROOT / "docs" / "equations.md").read_text(), re.M)
    assert len(rows) == len(_documented())
    for lab, where, meaning in rows:
        assert re.fullmatch(r"eq\. \(\d+\)|unnumbered display|(Section|Lemma|Theorem|Definition|Table|Figure) "
                            r"[\d.]+", where.strip()), (lab, where)
        assert meaning.strip(), lab


def test_code_and_docs_cite_no_design_notes_or_issue_numbers():
    bad = re.compile(r"DESIGN\.md|\b[Ii]ssue #?\d+")
    hits = [str(p.relative_to(ROOT)) for p in _files()
            if p.relative_to(ROOT).parts[0] in ("switchobs_core", "docs") and bad.search(p.read_text())]
    assert not hits, hits
