"""`switchobs design --gains kalman`, `show` and `simulate` with a Kalman table, and the noise
model from a system file: what a user types, with the numbers and the one-line errors."""

from __future__ import annotations

import json

import numpy as np
import pytest

from switchobs_core.cli import main
from switchobs_core.exceptions import NoiseModelError
from switchobs_core.model.scenarios import load_noise, load_system
from switchobs_core.table.gains import GainTable

CART = """name: cart_pair
states: [p1, v1, p2, v2]
A: [[0, 1, 0, 0], [0, -0.1, 0, 0], [0, 0, 0, 1], [0, 0, 0, 0.05]]
channels:
  - {name: left,  C: [[1, 0, 0, 0]]}
  - {name: right, C: [[1, 0, -1, 0]]}
"""


@pytest.fixture(scope="module")
def ktable(tmp_path_factory):
    out = tmp_path_factory.mktemp("k") / "k.json"
    assert main(["design", "paper", "--cycle", "2,0.6", "--gains", "kalman", "--rate", "50",
                 "--meas-noise", "0.002", "-o", str(out)]) == 0
    return out


def test_design_kalman_json_and_show(tmp_path, capsys):
    out = tmp_path / "seq.json"
    assert main(["design", "paper", "--cycle", "4,0.5", "--cycle", "2,0.4", "--gains", "kalman", "--rate", "20",
                 "--process-noise", "0.05", "-o", str(out), "--json"]) == 0
    s = json.loads(capsys.readouterr().out)
    (k,) = s["kalman"]
    assert s["family"] == "kalman" and k["rate_hz"] == 20 and k["period_samples"] == 120      # (4 + 2) s * 20 Hz
    assert [c["tau"] for c in k["cycles"]] == [4.0, 2.0]
    assert k["noise"]["Q_c"][0][0] == pytest.approx(0.05**2)
    assert 0 < k["period_error_transition"]["spectral_radius"] < 1
    table = GainTable.load(out, system=load_system("paper"))
    assert table.family == "kalman"
    assert main(["show", str(out), "--system", "paper"]) == 0
    text = capsys.readouterr().out
    assert "family kalman" in text and "(4 s, 0.5), (2 s, 0.4)" in text and "120 samples" in text


@pytest.mark.parametrize("args,match", [
    (["--gains", "kalman"], "--rate HZ"),
    (["--gains", "kalman", "--rate", "31.4159265"], "whole number|integ|rational|sample"),
    (["--gains", "kalman", "--rate", "50", "--meas-noise", "-1"], "measurement_std"),
    (["--gains", "kalman", "--rate", "50", "--robust", "0.8,1.2"], "known schedule"),
    (["--rate", "50"], "belong to --gains kalman"),
])
def test_design_kalman_errors_are_one_line(tmp_path, capsys, args, match):
    assert main(["design", "paper", "--cycle", "2,0.6", *args, "-o", str(tmp_path / "x.json")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and err.startswith("switchobs design: error:")
    assert __import__("re").search(match, err), err
    assert not (tmp_path / "x.json").exists()


def test_simulate_with_kalman_table(ktable, capsys):
    assert main(["simulate", "paper", "--table", str(ktable), "--schedule", "periodic:2,0.6", "--rate", "50",
                 "--t-end", "10", "--json"]) == 0
    s = json.loads(capsys.readouterr().out)
    assert s["gain_family"] == "kalman" and s["final_paper_bound"] is None and s["envelope_violations"] is None
    # noise-free: the Kalman gains take the error from 0.1-scale to below 1e-6 within 10 s
    assert s["final_error"] < 1e-6 * s["e0"]
    assert isinstance(s["exact_bound_violations"], int)
    assert main(["simulate", "paper", "--table", str(ktable), "--t-end", "5"]) == 2
    assert "sampled filter" in capsys.readouterr().err


def test_noise_section_of_a_system_file(tmp_path):
    f = tmp_path / "cart.yaml"
    f.write_text(CART + "noise:\n  measurement_std: [0.01, 0.02]\n  process_std: 0.1\n  P0: [1, 2, 3, 4]\n")
    sys_ = load_system(f)                      # the system loader ignores the noise section
    nm = load_noise(f, sys_)
    assert nm.R(1)[0, 0] == pytest.approx(1e-4) and nm.R(2)[0, 0] == pytest.approx(4e-4)
    assert np.allclose(nm.Q_c, 0.01 * np.eye(4)) and np.allclose(np.diag(nm.P0), [1, 2, 3, 4])
    assert load_noise(f, sys_, meas_std=0.5).R(2)[0, 0] == pytest.approx(0.25)     # --meas-noise wins
    f.write_text(CART + "noise:\n  measurment_std: 0.01\n")
    with pytest.raises(NoiseModelError, match="unknown key"):
        load_noise(f, load_system(f))


def test_certify_a_kalman_table_is_refused_with_one_line(ktable, capsys):
    """A Kalman table holds no LMI cycle design: `certify` says so (it printed empty tables and
    exited 0)."""
    assert main(["certify", str(ktable)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and err.startswith("switchobs certify: error:"), err
    assert "nothing to certify: this table holds kalman gains" in err


def test_a_table_over_the_json_limit_is_written_as_npz_and_loads(tmp_path, capsys):
    """A Kalman table of many phases (the paper's model at 500 Hz: 7725 phases, a 25 MiB JSON) asked
    for as JSON: `design` writes the binary container beside it and says so in one line; `show`,
    `simulate` and GainTable.load (the nodes' loader) read it; a small table stays JSON."""
    out = tmp_path / "big.json"
    assert main(["design", "paper", "--cycle", "2,0.6", "--gains", "kalman", "--rate", "500", "-o", str(out),
                 "--json"]) == 0
    cap = capsys.readouterr()
    s = json.loads(cap.out)
    npz = tmp_path / "big.npz"
    assert s["output"] == str(npz) and npz.is_file() and not out.exists()
    (note,) = cap.err.splitlines()
    assert note == (f"note: the table's JSON would be at least 25 MiB, above the 16 MiB a JSON gain table may have: "
                    f"wrote the binary container {npz} instead (switchobs show, simulate and the nodes load it; name "
                    "the output .npz to choose it)")
    assert npz.stat().st_size < 16 * 2 ** 20
    table = GainTable.load(npz, system=load_system("paper"))
    assert table.family == "kalman"
    assert main(["show", str(npz), "--system", "paper"]) == 0
    assert "family kalman" in capsys.readouterr().out
    assert main(["simulate", "paper", "--table", str(npz), "--rate", "500", "--t-end", "0.2"]) == 0
    capsys.readouterr()
    # a table that fits stays what was asked for, without a note
    small = tmp_path / "small.json"
    assert main(["design", "paper", "--cycle", "2,0.6", "--gains", "kalman", "--rate", "20", "-o", str(small)]) == 0
    cap = capsys.readouterr()
    assert small.is_file() and "note:" not in cap.err and f"wrote {small}" in cap.out


def test_simulate_with_the_phase_bound(ktable, capsys):
    """``--bound phase``: the same estimates, the noise bound never below the error, looser than the
    ellipsoid's within 20x once on the table's periodic grid."""
    out = {}
    for bound in ("ellipsoid", "phase"):
        assert main(["simulate", "paper", "--table", str(ktable), "--schedule", "periodic:2,0.6", "--rate", "50",
                     "--t-end", "20", "--noise", "0.001", "--noise-max", "0.003", "--bound", bound, "--json"]) == 0
        out[bound] = json.loads(capsys.readouterr().out)
    e, p = out["ellipsoid"], out["phase"]
    assert p["cycle_end_errors"] == e["cycle_end_errors"]
    assert p["noise_bound_violations"] == 0 == e["noise_bound_violations"]
    assert e["final_noise_bound"] < p["final_noise_bound"] < 20 * e["final_noise_bound"]
