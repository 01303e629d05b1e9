"""Refusals of bad input by the command-line tools: every case exits non-zero with one line on
stderr (at most 3 lines, no traceback) within 30 s and 4 GB of address space, or, where the input
is valid, does not lose anything silently."""

from __future__ import annotations

import errno
import json
import os
import stat
import time

import numpy as np
import pytest
from refusals import assert_refused, switchobs, switchobs_bag

from switchobs_core.cli import main as switchobs_main


# ------------------------------------------------------------------ output files
def test_design_output_that_is_not_a_regular_file_is_refused_untouched(tmp_path, fifo, device):
    """`design -o DIR` was an IsADirectoryError traceback (its temporary file created in DIR's
    parent); `-o /dev/null` replaced the device with a regular file (as root)."""
    for target, kind in ((tmp_path, "a directory"), (fifo, "a FIFO"), (device, "a character device")):
        # one fresh interpreter per tool: the process's own imports and exit path (the others run
        # forked from a helper with the tools imported: forkserver.py)
        res = switchobs("design", "paper", "--cycle", "2,0.6", "-o", target, fresh=target == tmp_path)
        assert_refused(res, str(target), kind, "refusing to replace it", code=2)
    assert stat.S_ISFIFO(os.stat(fifo).st_mode) and stat.S_ISCHR(os.stat(device).st_mode)
    assert not [p for p in tmp_path.parent.iterdir() if p.name.endswith(".tmp")]


def test_plot_onto_a_device_or_a_full_disk_is_one_line(paper_tables, device, tmp_path, monkeypatch, capsys):
    res = switchobs("simulate", "paper", "--table", paper_tables["periodic"], "--t-end", "4", "--plot", device)
    assert_refused(res, "--plot", "character device", code=2)
    import matplotlib.figure

    def full(self, *a, **k):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(matplotlib.figure.Figure, "savefig", full)
    code = switchobs_main(["simulate", "paper", "--table", paper_tables["periodic"], "--t-end", "4",
                           "--plot", str(tmp_path / "e.png")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "No space left on device" in err[0] and "e.png" in err[0], err


@pytest.mark.parametrize("flag, value, needles", [
    ("--e0", "1e308", ("--e0 must be in [0, 1e+50]",)),                      # RuntimeWarnings, then refused
    ("--process-noise", "1e200", ("--process-noise", "standard deviation")),  # OverflowError traceback
    ("--seed", "-1", ("--seed must be an integer",)),                         # ValueError traceback
])
def test_simulate_numbers_within_range(flag, value, needles, paper_tables):
    res = switchobs("simulate", "paper", "--table", paper_tables["periodic"], "--t-end", "4", flag, value)
    assert_refused(res, *needles, code=2)


# ------------------------------------------------------------------ sizes
@pytest.mark.parametrize("args, needles", [
    (("design", "paper", "--gains", "kalman", "--cycle", "2,0.6", "--rate", "1e9", "-o", "{tmp}/k.json"),
     ("2e+09 samples per period", "TiB", "beyond the budget of 1 GiB")),
    (("plan", "paper", "--rate", "1e9"), ("4e+09 samples", "beyond the budget of 1 GiB", "--rate")),
    (("plan", "paper", "--rate", "50", "--tau-max", "1e9"), ("tau_max 1e+09 s", "beyond the budget")),
    (("plan", "paper", "--rate", "20", "--plot", "{tmp}/m.png", "--map-size", "100000"), ("--map-size", "[3, 64]")),
    (("certify", "{table}", "--ratio-cycles", "1000000000"), ("--ratio-cycles", "[1, 1000]")),
])
def test_sizes_are_refused_up_front_with_the_amount(args, needles, tmp_path, paper_tables):
    t0 = time.monotonic()
    res = switchobs(*(a.format(tmp=tmp_path, table=paper_tables["periodic"]) for a in args))
    assert_refused(res, *needles, code=2)
    assert time.monotonic() - t0 < 15


def test_bag_generate_size_refused_before_the_folder_is_made(tmp_path):
    res = switchobs_bag("generate", tmp_path / "g", "--duration", "1e9", "--rate", "1e6", fresh=True)
    assert_refused(res, "1e+15 ticks", "beyond the budget of 1 GiB", code=2)
    assert not (tmp_path / "g").exists()


@pytest.mark.parametrize("args, needles", [
    (("play", "{bag}", "--settle", "1e300"), ("--settle", "[0, 1e+06] s")),     # time.sleep OverflowError
    (("play", "{bag}", "--rate", "1e-300"), ("speed factor",)),
    (("play", "{bag}", "--wait-timeout", "nan"), ("--wait-timeout",)),
    (("record", "{tmp}/r", "--duration", "1e300"), ("--duration",)),
    (("record", "{tmp}/r", "--count", "-1"), ("--count",)),
])
def test_play_and_record_waits_within_range(args, needles, bag, tmp_path):
    res = switchobs_bag(*(a.format(bag=bag, tmp=tmp_path) for a in args))
    assert_refused(res, *needles, code=2)
    assert not (tmp_path / "r").exists()


# ------------------------------------------------------------------ input files
def test_a_fifo_where_a_file_is_read_never_blocks(fifo, bag, tmp_path):
    """--table, a params file, a system YAML, a bag's data file and its metadata.yaml: a FIFO
    blocked forever."""
    assert_refused(switchobs("simulate", "paper", "--table", fifo), "gain table", "FIFO", code=2)
    assert_refused(switchobs("design", fifo, "--cycle", "2,0.6", "-o", tmp_path / "t.json"), "FIFO", code=2)
    assert_refused(switchobs_bag("estimate", bag, "--csv", tmp_path / "e.csv", "--params-file", fifo), "FIFO",
                   code=2)
    for name in ("in.mcap", "metadata.yaml"):
        b = tmp_path / f"b_{name}"
        b.mkdir()
        for f in bag.iterdir():
            if f.name != name:
                (b / f.name).write_bytes(f.read_bytes())
        os.mkfifo(b / name)
        assert_refused(switchobs_bag("estimate", b, "--csv", tmp_path / "e.csv"), name, "FIFO", code=2)


def test_bag_metadata_and_directory_data_file_limits(bag, tmp_path):
    big = tmp_path / "big"
    big.mkdir()
    for f in bag.iterdir():
        (big / f.name).write_bytes(f.read_bytes())
    with (big / "metadata.yaml").open("a") as fh:
        fh.write(" " * (2 << 20))
    assert_refused(switchobs_bag("info", big), "metadata.yaml", "larger than 1 MiB", code=2)
    d = tmp_path / "d"
    d.mkdir()
    (d / "metadata.yaml").write_bytes((bag / "metadata.yaml").read_bytes())
    (d / "in.mcap").mkdir()
    assert_refused(switchobs_bag("info", d), "in.mcap", "a directory", code=2)


# ------------------------------------------------------------------ values in params files
def _params(tmp_path, body: str):
    p = tmp_path / "p.yaml"
    p.write_text("estimator:\n  ros__parameters:\n" + body)
    return p


@pytest.mark.parametrize("body, needles", [
    ("    future_tolerance: 1.0e300\n", ("future_tolerance", "(0, 1e+06] s")),
    ("    sensor_timeout: 1.0e10\n", ("sensor_timeout", "int64")),
    ("    e0: 1.0e308\n", ("'e0'", "[0, 1e+50]")),
    ("    noise:\n      max: 1.0e150\n", ("noise.max", "1e+50")),
    ("    initial_estimate: [1.0e300, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]\n",
     ("initial_estimate", "1e+50")),
    ("    schedule:\n      mode: sequence\n      h: [" + ", ".join(["1.0"] * 60_000) + "]\n",
     ("30000 cycles given, at most 1000",)),
    ("    rate: 1.0e9\n    gain_family: kalman\n    gain_table: ''\n", ("'rate'", "1e+06")),
    ("    diagnostics_period: 1.0e12\n", ("diagnostics_period", "timer")),
])
def test_params_values_out_of_range_are_refused(body, needles, bag, tmp_path, paper_tables):
    """Finite values too large for what follows: tracebacks (future_tolerance 1e300, e0 1e308),
    silent loss (noise.max 1e150, initial_estimate 1e300: half the measurements unanswered, exit 0),
    an O(n^2) loop (30 000 cycles), a 15 GiB allocation (rate 1e9)."""
    body = body if "gain_table" in body else body + f"    gain_table: {paper_tables['periodic']}\n"
    res = switchobs_bag("estimate", bag, "--csv", tmp_path / "e.csv", "--params-file", _params(tmp_path, body))
    assert_refused(res, *needles, code=2)
    assert not (tmp_path / "e.csv").exists()


def test_kalman_design_at_start_up_too_large_is_refused(bag, tmp_path):
    res = switchobs_bag("estimate", bag, "--csv", tmp_path / "e.csv", "-p", "gain_family:=kalman", "-p",
                        "rate:=100000.0", "-p", f"gain_table_cache_dir:={tmp_path / 'cache'}")
    assert_refused(res, "samples per period", "beyond the budget of 1 GiB", code=2)


# ------------------------------------------------------------------ nothing lost silently
def test_bag_with_topics_and_no_messages_is_refused(tmp_path, paper_tables):
    from switchobs_ros.bag.io import CONTRACT_TYPES, BagOut

    with BagOut(tmp_path / "empty", "mcap") as out:
        for t in ("/camera/active_channel", "/camera/pose", "/target/pose"):
            out.add(t, CONTRACT_TYPES[t])
    res = switchobs_bag("estimate", tmp_path / "empty", "-o", tmp_path / "out", "--gain-table",
                        paper_tables["periodic"])
    assert_refused(res, "hold no messages", "nothing to estimate", code=2)
    assert not (tmp_path / "out").exists()


def test_strict_exits_non_zero_and_names_the_reasons(bag, tmp_path, paper_tables, monkeypatch, capsys):
    """Every third observer update not finite (withheld, reset): without --strict exit 0 and the
    summary names the reason; with --strict exit 4 and one line on stderr."""
    from switchobs_core.runtime.observer import SwitchedObserver
    from switchobs_ros.bag.cli import main as bag_main
    from switchobs_ros.bag.cli.estimate import STRICT_EXIT

    update = SwitchedObserver.update
    calls = [0]

    def every_third_nan(self, *a, **k):
        calls[0] += 1
        x = update(self, *a, **k)
        return x * np.nan if calls[0] % 3 == 0 else x

    monkeypatch.setattr(SwitchedObserver, "update", every_third_nan)
    base = ["estimate", str(bag), "--gain-table", paper_tables["periodic"]]
    assert bag_main(base + ["--csv", str(tmp_path / "a.csv")]) == 0
    out = capsys.readouterr()
    assert "valid measurements without an estimate" in out.out and "non_finite_estimate" in out.out
    assert bag_main(base + ["--csv", str(tmp_path / "b.csv"), "--strict", "--json"]) == STRICT_EXIT == 4
    out = capsys.readouterr()
    err = out.err.strip().splitlines()
    assert len(err) == 1 and "--strict" in err[0] and "non_finite_estimate" in err[0], err
    assert json.loads(out.out)["unanswered"]["non_finite_estimate"] > 0
    monkeypatch.setattr(SwitchedObserver, "update", update)
    assert bag_main(base + ["--csv", str(tmp_path / "c.csv"), "--strict"]) == 0


def test_report_on_an_envelope_holding_inf_writes_valid_json(bag, tmp_path, paper_tables):
    from rclpy.serialization import deserialize_message, serialize_message
    from std_msgs.msg import Float64MultiArray

    from switchobs_ros.bag.io import BagIn, BagOut

    est = tmp_path / "est"
    assert switchobs_bag("estimate", bag, "-o", est, "--gain-table", paper_tables["periodic"]).returncode == 0
    with BagIn(est) as b:
        msgs, topics = b.messages(order="file"), dict(b.topics)
    with BagOut(tmp_path / "inf", "mcap") as out:
        for t, ty in topics.items():
            out.add(t, ty)
        for m in msgs:
            data = m.data
            if m.topic == "/estimator/envelope":
                a = deserialize_message(data, Float64MultiArray)
                a.data = [*a.data[:-2], float("inf"), float("inf")]
                data = serialize_message(a)
            out.write(m.topic, m.log_ns, data)
    res = switchobs_bag("report", tmp_path / "inf", "-o", tmp_path / "r.png", "--json")
    assert res.returncode == 0 and "Traceback" not in res.stderr, res.stderr

    def no_constant(name):
        raise AssertionError(f"{name} is not JSON")

    rep = json.loads(res.stdout, parse_constant=no_constant)
    assert rep["passes"][0]["final_exact_bound"] is None and rep["passes"][0]["final_paper_bound"] is None
    res = switchobs_bag("report", tmp_path / "inf", "-o", tmp_path)
    assert_refused(res, "a directory", code=2)


def test_output_decimation_and_generated_stamps_within_range(tmp_path):
    """`output.*_every` is an integer in [0, 1e9] (an int64 parameter; beyond it nothing is
    published); a generated bag's stamps fit `builtin_interfaces/Time.sec` (an int32)."""
    from switchobs_ros.config import EstimatorConfig
    from switchobs_ros.params import ConfigError

    for name in ("output.envelope_every", "output.odometry_every", "output.covariance_every", "output.typed_every"):
        assert EstimatorConfig.from_values({name: 10**9})[name] == 10**9
        for bad in (10**9 + 1, -1):
            with pytest.raises(ConfigError, match=rf"'{name}'.*\[0, 1000000000\]"):
                EstimatorConfig.from_values({name: bad})
    res = switchobs_bag("generate", tmp_path / "late", "--clock-start", "2147483000", "--duration", "1000")
    assert_refused(res, "--clock-start + --duration", "int32", code=2)
    assert not (tmp_path / "late").exists()
