"""Tests of ``switchobs simulate`` and ``switchobs certify`` (in process, no subprocess)."""

from __future__ import annotations

import json

import pytest
from _paper_designs import paper_table

from switchobs_core.cli import main


@pytest.fixture(scope="module")
def table_path(paper, tmp_path_factory):
    path = tmp_path_factory.mktemp("cli") / "gains.json"
    paper_table(paper).save(path)
    return path


def test_simulate_json(table_path, capsys, tmp_path):
    png = tmp_path / "sim.png"
    rc = main(["simulate", "paper", "--table", str(table_path), "--schedule", "periodic:2,0.6",
               "--t-end", "20", "--json", "--plot", str(png)])
    out = json.loads(capsys.readouterr().out)
    assert rc == 0 and png.stat().st_size > 10_000
    assert out["final_error"] < 1e-3 and out["cycles"] == 10          # 20 s of (2 s, 0.6): every cycle, the last too
    ends = out["cycle_end_errors"]
    assert all(b < a for a, b in zip(ends, ends[1:]))
    assert out["exact_bound_violations"] == 0


def test_simulate_sampled_text(table_path, capsys):
    rc = main(["simulate", "paper", "--table", str(table_path), "--schedule", "sequence:4,0.5;3,0.6;3,0.6;2,0.4",
               "--t-end", "12", "--rate", "100", "--noise", "0.001"])
    out = capsys.readouterr().out
    assert rc == 0 and "sampled at 100 Hz" in out and "paper bound (claim)" in out


def test_certify_json_side_by_side(table_path, capsys):
    rc = main(["certify", str(table_path), "--system", "paper", "--sequence", "4,0.5", "3,0.6", "2,0.4",
               "--json", "--no-box"])
    rep = json.loads(capsys.readouterr().out)
    assert rc == 0
    d = next(e for e in rep["designs"] if e["cycle"] == "(2 s, 0.6)")
    assert d["paper"]["claims_convergence"] and d["sound"]["converges"]
    assert d["envelope_ratio"]["worst"][1] > 1.08  # the paper's z_2 is exceeded (proof gap)
    assert rep["sequence"]["sound"]["verified"] and rep["sequence"]["sound"]["converges_any_order"]
    assert rep["sequence"]["sound"]["margin"] >= 5e-5  # proved 1e-4 above the SDP's edge, not at it


def test_certify_text_labels(table_path, capsys):
    assert main(["certify", str(table_path), "--no-box"]) == 0
    out = capsys.readouterr().out
    assert "claim" in out and "verified" in out and "env. ratio" in out


@pytest.mark.parametrize("argv,match", [
    (["simulate", "paper", "--table", "/nonexistent/gains.json"], "error"),
    (["simulate", "paper", "--table", "TABLE", "--schedule", "weekly:1"], "unknown schedule"),
    (["simulate", "paper", "--table", "TABLE", "--rate", "-5"], "rate"),
    (["certify", "TABLE", "--ratio-cycles", "0", "--system", "paper"], "ratio-cycles"),
])
def test_errors_exit_2(table_path, capsys, argv, match):
    argv = [str(table_path) if a == "TABLE" else a for a in argv]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert match in err and len(err.strip().splitlines()) == 1


@pytest.mark.parametrize("extra, label, guaranteed", [
    (["--rate", "100", "--hold", "measurement"], "guaranteed bound", "measurement hold"),
    (["--rate", "100"], "guaranteed bound", "innovation hold"),
    ([], "guaranteed bound", "continuous outputs"),
    (["--rate", "100", "--noise", "0.05", "--noise-max", "0.1"], "guaranteed bound (bounded noise)",
     "declared noise"),
    (["--rate", "100", "--noise", "0.05"], "noise-free bound", None),
])
def test_simulate_guaranteed_column_holds_or_is_labelled_noise_free(table_path, capsys, extra, label, guaranteed):
    """The column called 'guaranteed bound' is >= the error at every cycle end in every setting
    where one holds (noise-free, or noise within a declared --noise-max), and "verified"; with
    noise and no declared bound the column is the noise-free bound, labelled as such and never
    called guaranteed."""
    argv = ["simulate", "paper", "--table", str(table_path), "--t-end", "8", "--e0", "0.1"] + extra
    assert main(argv) == 0
    out = capsys.readouterr().out
    status = next(line for line in out.splitlines() if line.startswith(label + ":"))
    rows = [line.split() for line in out.splitlines() if line[:1].isdigit()]
    assert len(rows) >= 3
    if guaranteed is None:
        assert "NOT a guarantee" in status and "guaranteed" not in out
    else:
        assert guaranteed in status and "verified at all" in status
        assert all(float(r[2]) <= float(r[3]) for r in rows)


def test_simulate_plot_name_checked_up_front(table_path, capsys, tmp_path):
    """--plot with a file name matplotlib cannot write: one line, exit 2, before any simulation."""
    assert main(["simulate", "paper", "--table", str(table_path), "--plot", str(tmp_path / "x.txt")]) == 2
    err = capsys.readouterr().err
    assert "--plot" in err and ".png" in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "x.txt").exists()


def test_simulate_zero_initial_error_bound_is_the_rounding_floor(table_path, capsys):
    """--e0 0: the estimate starts at the truth; the guaranteed bound is the rounding's, not 0,
    and never below the computed error (it was 0 below an error of 5.8e-15)."""
    argv = ["simulate", "paper", "--table", str(table_path), "--t-end", "10", "--rate", "100", "--e0", "0", "--json"]
    assert main(argv) == 0
    s = json.loads(capsys.readouterr().out)
    assert s["e0"] == 0 and s["exact_bound_violations"] == 0
    assert 0 < s["final_error"] < s["final_exact_bound"] < 1e-6


def test_simulate_warns_when_a_random_schedule_breaks_a2(paper, tmp_path, capsys):
    """A random schedule whose residence times leave the table's robust box: a warning naming both."""
    path = tmp_path / "robust.json"
    paper_table(paper, robust=(0.8, 1.2)).save(path)
    base = ["simulate", "paper", "--table", str(path), "--t-end", "6"]
    assert main(base + ["--schedule", "random:0.5,1.5"]) == 0
    err = capsys.readouterr().err
    assert "A2" in err and "[0.5, 1.5]" in err and "[0.8, 1.2]" in err
    assert main(base + ["--schedule", "random:0.9,1.1"]) == 0
    assert "A2" not in capsys.readouterr().err


def _argparse_one_line(argv, capsys) -> str:
    with pytest.raises(SystemExit) as ex:
        main(argv)
    assert ex.value.code == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err, err
    return err


def test_negative_cycle_is_checked_not_taken_for_an_option(capsys, tmp_path):
    """`--cycle -2,0.6` met argparse's "expected one argument"; now the value's own check speaks."""
    err = _argparse_one_line(["design", "paper", "--cycle", "-2,0.6", "-o", str(tmp_path / "x.json")], capsys)
    assert "tau must be > 0" in err and "--cycle" in err


def test_cycle_too_long_to_represent_is_refused(paper, capsys, tmp_path):
    """`--cycle 1e9,0.6` designed and said "converges" (f = 0): e^(A tau) leaves double precision.
    The longest tau offered is where ||A||_2 tau reaches 600 (e^600 is still a double, e^710 not),
    with the smaller of the norms of A and of A in balanced units (the units of the state do not count)."""
    import math

    import numpy as np

    from switchobs_core.numerics.scaling import balanced_norm

    nA = min(float(np.linalg.norm(paper.A, 2)), balanced_norm(paper.A))
    longest = 600.0 / nA
    assert math.isfinite(math.exp(nA * longest))
    assert main(["design", "paper", "--cycle", "1e9,0.6", "-o", str(tmp_path / "x.json")]) == 2
    err = capsys.readouterr().err
    assert "too long for this system" in err and f"use tau <= {longest:.4g} s" in err
    assert len(err.strip().splitlines()) == 1


def test_messages_speak_flags_not_api_or_latex(capsys, tmp_path, table_path):
    """No LaTeX label ("Sec. s:LMI_Gain", "Theorem t:main") in any --help; a design without a
    schedule names the flags; `show` prints the margin in words, not a Python dict."""
    import re

    for cmd in ("design", "show", "reproduce", "simulate", "certify", "plan"):
        with pytest.raises(SystemExit):
            main([cmd, "--help"])
        out = capsys.readouterr().out
        assert not re.search(r"\b[setfl]:[A-Za-z_]+", out), (cmd, re.search(r"\b[setfl]:[A-Za-z_]+", out))
    assert main(["design", "paper", "-o", str(tmp_path / "x.json")]) == 2
    err = capsys.readouterr().err
    assert "--cycle TAU,S" in err and "--robust" in err and "in cycles" not in err
    assert main(["show", str(table_path)]) == 0
    out = capsys.readouterr().out
    assert "{" not in out and "eta margin 5 %" in out


def test_show_into_a_closed_pipe_is_quiet(table_path):
    """`switchobs show T | head -1`: the reader went away; no BrokenPipeError traceback, exit 0.
    (The read end is closed before the command writes, so the broken pipe is certain.)"""
    import subprocess
    import sys

    p = subprocess.Popen([sys.executable, "-m", "switchobs_core.cli", "show", str(table_path), "--json"],
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    p.stdout.close()
    err = p.stderr.read().decode()
    assert p.wait(timeout=60) == 0, err
    assert "Traceback" not in err and "BrokenPipe" not in err, err
