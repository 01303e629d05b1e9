"""The `switchobs` design-side commands, run in-process and as a subprocess."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from switchobs_core import paper as P
from switchobs_core.cli import main


def test_design_show_round_trip(tmp_path, capsys):
    out = tmp_path / "g.json"
    assert main(["design", "paper", "--cycle", "2,0.6", "--robust", "0.8,1.2", "-o", str(out), "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["designs"][0]["eta_min"] == pytest.approx([1.5, 3.24], abs=0.01)
    assert summary["robust"]["h_bounds"] == [0.8, 1.2]
    assert main(["show", str(out), "--system", "paper"]) == 0
    text = capsys.readouterr().out
    assert "matches system 'paper'" in text and "(2 s, 0.6)" in text and "robust h in [0.8, 1.2]" in text


def test_design_n_channels_from_yaml(tmp_path, capsys):
    cfg = tmp_path / "three.yaml"
    cfg.write_text("scenario: camera_agents\nagents: 3\n")
    out = tmp_path / "g3.json"
    assert main(["design", str(cfg), "--cycle-h", "1,1,1", "--delta", "0.95", "-o", str(out), "--json"]) == 0
    s = json.loads(capsys.readouterr().out)
    assert len(s["designs"][0]["eta"]) == 3 and s["designs"][0]["paper_condition_holds"]


def test_reproduce_json_matches_paper(capsys):
    assert main(["reproduce", "--json"]) == 0
    res = json.loads(capsys.readouterr().out)
    assert res["mu_ours"] == pytest.approx(list(P.MU), abs=5e-5)
    for row, (_, emin, _) in zip(res["rows"], P.TABLE):
        assert row["eta_min_ours"] == pytest.approx(list(emin), abs=0.01)


def test_errors_are_one_line_exit_2(tmp_path, capsys):
    assert main(["design", "nope", "--cycle", "2,0.6", "-o", str(tmp_path / "x.json")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("switchobs design: error: unknown scenario 'nope'") and "\n" not in err
    bad = tmp_path / "bad.json"
    bad.write_text("{")
    assert main(["show", str(bad)]) == 2
    assert "truncated" in capsys.readouterr().err
    with pytest.raises(SystemExit) as e:
        main(["design", "paper", "--cycle", "2,1.5", "-o", str(tmp_path / "y.json")])
    assert e.value.code == 2
    assert "s must lie in (0, 1)" in capsys.readouterr().err


def test_module_entry_point(tmp_path):
    r = subprocess.run([sys.executable, "-m", "switchobs_core.cli", "--version"], capture_output=True, text=True)
    assert r.returncode == 0 and r.stdout.startswith("switchobs ")


def test_design_with_explicit_eta(tmp_path, capsys):
    """--eta sets the rates: the paper's selected (1.6, 3.5) for (2 s, 0.6) meets its condition;
    rates below eta_min are designed and verified, and the table says the condition fails."""
    out = tmp_path / "eta.json"
    assert main(["design", "paper", "--cycle", "2,0.6", "--eta", "1.6,3.5", "-o", str(out), "--json"]) == 0
    (d,) = json.loads(capsys.readouterr().out)["designs"]
    assert d["eta"] == [1.6, 3.5] and d["paper_condition_holds"] and max(d["f"]) < 0.99
    assert main(["design", "paper", "--cycle", "2,0.6", "--eta", "1,1", "-o", str(out), "--json"]) == 0
    (d,) = json.loads(capsys.readouterr().out)["designs"]
    assert d["eta"] == [1.0, 1.0] and not d["paper_condition_holds"] and min(d["f"]) > 0.99
    assert main(["design", "paper", "--cycle", "2,0.6", "--eta", "1.6", "-o", str(out)]) == 2
    assert "must give 2 positive rates" in capsys.readouterr().err
