"""``switchobs_bag estimate`` writes its outputs as the estimates come: the CSV and the bag of a run
that keeps nothing in memory (``keep=False``, what the command runs) are those of a run that keeps
every estimate, and its result holds only their number; a selection of outputs writes those outputs as a
full run does; the MCAP records are the bytes rosbags writes."""

from __future__ import annotations

import importlib
import json
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from rclpy.serialization import serialize_message
from rosbags.rosbag2 import writer as rosbags_writer
from ruamel.yaml import YAML
from std_msgs.msg import Float64MultiArray

import msg_bridge as mb
from switchobs_ros.bag import cdr, mcap_records
from switchobs_ros.bag import io as bag_io
from switchobs_ros.bag.cli import main as bag_main
from switchobs_ros.bag.cli.estimate import DEFAULT_OUTPUTS, outputs_of
from switchobs_ros.bag.estimate import OUTPUTS, CsvWriter, estimate, estimator_params, write_csv
from switchobs_ros.bag.generate import GenerateConfig, generate
from switchobs_ros.bag.io import BagError, BagIn, BagOut, deserialize


@pytest.fixture(scope="module")
def bag(tmp_path_factory):
    d = tmp_path_factory.mktemp("stream")
    generate(d / "in", GenerateConfig(duration=2.0, noise_std=0.01, seed=5), "mcap")
    return d / "in"


def _params(paper_tables):
    return estimator_params(overrides={"gain_table": paper_tables["periodic"], "e0": 5.0,
                                       "output.covariance_every": 1})


def get_message(name: str) -> type:
    """The rclpy class of ``pkg/msg/Type``."""
    pkg, sub, cls = name.split("/")
    return getattr(importlib.import_module(f"{pkg}.{sub}"), cls)


def _messages(path) -> list:
    """(topic, log time, message) in file order, deserialised (CDR padding bytes are not content)."""
    with BagIn(path) as b:
        types = dict(b.topics)
        return [(m.topic, m.log_ns, deserialize(m, get_message(types[m.topic])))
                for m in b.messages(order="file")]


def test_streamed_outputs_equal_the_kept_ones(bag, paper_tables, tmp_path):
    p = _params(paper_tables)
    kept = estimate(bag, p, out=tmp_path / "kept", csv=tmp_path / "kept.csv")
    streamed = estimate(bag, p, out=tmp_path / "streamed", csv=tmp_path / "streamed.csv", keep=False)
    assert kept.count == kept.stamps.size > 50 and streamed.count == kept.count
    assert streamed.stamps.size == 0 and streamed.x_hat.size == 0 and streamed.P is None
    assert kept.P is not None and kept.P.shape == (kept.count, 12, 12)
    assert (tmp_path / "streamed.csv").read_bytes() == (tmp_path / "kept.csv").read_bytes()
    assert _messages(tmp_path / "streamed") == _messages(tmp_path / "kept")
    # the CSV of a kept result, written afterwards, is the same file
    write_csv(tmp_path / "after.csv", kept)
    assert (tmp_path / "after.csv").read_bytes() == (tmp_path / "kept.csv").read_bytes()
    rows = np.loadtxt(tmp_path / "kept.csv", delimiter=",", skiprows=1)
    np.testing.assert_array_equal(rows[:, 1:13], kept.x_hat)


def test_command_counts_what_it_streamed(bag, paper_tables, tmp_path, capsys):
    rc = bag_main(["estimate", str(bag), "--csv", str(tmp_path / "e.csv"), "--gain-table",
                   paper_tables["periodic"], "-p", "e0:=5.0", "--json"])
    assert rc == 0
    info = json.loads(capsys.readouterr().out)
    rows = (tmp_path / "e.csv").read_text().splitlines()
    assert info["estimates"] == len(rows) - 1 > 50


def test_array_template_takes_a_float_array_in_one_copy():
    """A covariance's doubles as a float64 array: the bytes of the same values as a list; a wrong
    length is refused."""
    n = 7
    labels = tuple(f"s{i}" for i in range(n))
    w = cdr.Template(mb.labelled_array(np.zeros(n * n), mb.covariance_labels(labels), 0), array=("data",))
    P = np.random.default_rng(0).standard_normal((n, n))
    as_list = w.bytes(array=[3, 456, *P.ravel().tolist()])
    assert w.bytes(array=np.concatenate(((3, 456), P.ravel()))) == as_list
    assert w.bytes(array=np.concatenate(((3, 456), P.T.ravel()))) != as_list
    with pytest.raises(ValueError):
        w.bytes(array=P.ravel())


def test_typed_estimate_template_is_the_writers_message():
    """The typed estimate patched into bytes serialised once (cdr.Template with two arrays, as
    switchobs_bag estimate writes it) reads back as the message StateEstimateWriter makes, with a
    covariance and without, at several stamps; a wrong length is refused."""
    from rclpy.serialization import deserialize_message
    from switchobs_msgs.msg import StateEstimate

    from msg_bridge.typed import StateEstimateWriter

    n = 9
    labels = tuple(f"agent{i}.p_x" for i in range(n))
    ref = StateEstimateWriter(labels, "world")
    rng = np.random.default_rng(1)
    for has_P in (True, False):
        w = cdr.Template(StateEstimateWriter(labels, "world").msg(np.zeros(n), 0, np.zeros((n, n)) if has_P else None),
                         stamp=("header", "stamp"), arrays=[("x",), ("covariance",)] if has_P else [("x",)])
        for stamp in (0, 1_500_000_001, 2 * 10 ** 18 + 7):
            x, P = rng.standard_normal(n), rng.standard_normal((n, n)) if has_P else None
            got = deserialize_message(w.bytes(stamp, arrays=(x,) if P is None else (x, P)), StateEstimate)
            assert got == deserialize_message(serialize_message(ref.msg(x, stamp, P)), StateEstimate)
            assert list(got.x) == x.tolist() and len(got.covariance) == (n * n if has_P else 0)
        with pytest.raises(ValueError):
            w.bytes(0, arrays=(np.zeros(n + 1),) if not has_P else (np.zeros(n), np.zeros(n)))


def test_selected_outputs_are_those_of_a_full_run(bag, paper_tables, tmp_path):
    """A run writing some outputs writes exactly their topics (and ``~/state``, the inputs, the
    diagnostics), each message for message as a run writing all of them; an unknown name is refused."""
    p = _params(paper_tables)
    estimate(bag, p, out=tmp_path / "all", keep=False)
    estimate(bag, p, out=tmp_path / "some", keep=False, outputs=("typed", "envelope"))
    full, some = _messages(tmp_path / "all"), _messages(tmp_path / "some")
    dropped = {"/estimator/covariance"} | {t for t, _, _ in full if t.endswith("/odom")}
    assert "/estimator/covariance" in {t for t, _, _ in full} and len(dropped) > 1
    assert some == [m for m in full if m[0] not in dropped]
    with pytest.raises(BagError, match="unknown output"):
        estimate(bag, p, out=tmp_path / "bad", outputs=("covariances",))


def test_outputs_option_names_the_outputs():
    assert outputs_of("all") == OUTPUTS and outputs_of("none") == ()
    assert outputs_of(" typed, covariance") == ("typed", "covariance")
    assert set(DEFAULT_OUTPUTS) == set(OUTPUTS) - {"covariance"}
    with pytest.raises(BagError, match="--outputs: unknown output odom "):
        outputs_of("typed,odom")


@pytest.mark.parametrize("storage", ["mcap", "sqlite3"])
def test_fast_records_write_the_bytes_rosbags_writes(tmp_path, monkeypatch, storage):
    """The MCAP records appended in one write (one message, or several at one log time: write_many) and
    the chunks closed with a struct per record (switchobs_ros.bag.mcap_records), and the YAML written
    without ruamel (switchobs_ros.bag.metadata_yaml), are byte for byte those of rosbags' own writer (the
    file and metadata.yaml), over chunk boundaries and out-of-order log times; sqlite3 keeps rosbags' path
    for the records."""
    rng = np.random.default_rng(3)
    topics = ["/a", "/b", "/c"]
    msgs = [(topics[int(rng.integers(3))], int(1_000_000 + rng.integers(-5000, 5000) + 1000 * k),    # serialised once:
             serialize_message(Float64MultiArray(data=rng.standard_normal(int(rng.integers(0, 3000))).tolist())))
            for k in range(400)]                                    # CDR padding bytes are not deterministic
    groups, k = [], 0                       # runs of 1-6 messages at one log time: written with write_many
    while k < len(msgs):
        m = int(rng.integers(1, 7))
        groups.append([(t, msgs[k][1], data) for t, _, data in msgs[k:k + m]])
        k += m
    msgs = [x for g in groups for x in g]

    def write(path):
        with BagOut(path, storage) as out:
            for t in topics:
                out.add(t, "std_msgs/msg/Float64MultiArray")
            for g in groups:
                if len(g) == 1:
                    out.write(*g[0])
                else:
                    out.write_many([t for t, _, _ in g], g[0][1], [d for _, _, d in g])
            return out

    with BagOut(tmp_path / "probe", storage) as probe:     # the fast path is taken for mcap only
        taken = getattr(probe._w.storage.write, "__func__", None) is mcap_records._write
    assert taken == (storage == "mcap")
    fast = write(tmp_path / "fast" / "b")          # the same name: the file's metadata record holds it
    monkeypatch.setattr(bag_io, "fast_records", lambda w: False)
    monkeypatch.setattr(bag_io, "fast_yaml", lambda: None)
    monkeypatch.setattr(rosbags_writer, "YAML", YAML)
    write(tmp_path / "slow" / "b")
    if storage == "mcap":
        a, b = (tmp_path / "fast" / "b" / "b.mcap").read_bytes(), (tmp_path / "slow" / "b" / "b.mcap").read_bytes()
        assert len(a) > 3 * 2 ** 20 and a == b          # several chunks
    meta = [(tmp_path / d / "b" / "metadata.yaml").read_bytes() for d in ("fast", "slow")]
    assert meta[0] == meta[1] and b"offered_qos_profiles" in meta[0]
    assert fast.count == len(msgs)
    got = [(m.topic, m.log_ns, m.data) for m in BagIn(tmp_path / "fast" / "b").messages(order="file")]
    assert got == msgs


@settings(max_examples=50, deadline=None)
@given(values=st.lists(st.floats(allow_nan=True, allow_infinity=True), min_size=2, max_size=40),
       stamp=st.integers(0, 2 ** 62))
def test_csv_rows_are_the_floats_reprs(tmp_path_factory, values, stamp):
    """Property: a CSV row is the stamp and each float's repr joined by commas (any doubles: signed
    zeros, subnormals, infinities, NaN)."""
    path = tmp_path_factory.mktemp("csv") / "e.csv"
    k = len(values) // 2
    w = CsvWriter(path, tuple(f"s{i}" for i in range(k)), tuple(f"e{i}" for i in range(len(values) - k)))
    w.row(stamp, np.array(values[:k], dtype=float), np.array(values[k:], dtype=float))
    w.close()
    row = path.read_text().splitlines()[1]
    assert row == f"{stamp}," + ",".join(map(repr, [float(v) for v in values]))


@settings(max_examples=60, deadline=None)
@given(x=st.lists(st.floats(allow_nan=True, allow_infinity=True), max_size=6),
       env=st.lists(st.sampled_from([0.0, -0.0, 187.77062051064496, 3.5e-06, 1e-320, -1.0, math.inf, math.nan, 0.1]),
                    min_size=0, max_size=40))
def test_csv_rows_with_repeated_envelope_values(tmp_path_factory, x, env):
    """Property: an envelope whose values repeat (each distinct value formatted once) gives the same row as
    each float's repr, signed zeros and NaN among them; an empty state or envelope part too."""
    path = tmp_path_factory.mktemp("csv") / "e.csv"
    w = CsvWriter(path, tuple(f"s{i}" for i in range(len(x))), tuple(f"e{i}" for i in range(len(env))))
    w.row(7, np.array(x, dtype=float), np.array(env, dtype=float))
    w.close()
    assert path.read_text().splitlines()[1] == "7," + ",".join(map(repr, [float(v) for v in x + env]))


def test_odometry_is_the_nodes_with_the_covariance(bag, paper_tables, tmp_path):
    """The bodies' odometries in the bag are the node's (the node's writer, msg_bridge.raw): each is
    ``body_odometry`` of its estimate with the covariance blocks of the estimate's P, at the node's
    decimation (``output.odometry_every``: every 3rd estimate here)."""
    p = dict(_params(paper_tables), **{"output.odometry_every": 3})
    kept = estimate(bag, p, out=tmp_path / "o", outputs=("odometry",))
    bodies = mb.bodies(kept.state_labels)
    odoms = [m for t, _, m in _messages(tmp_path / "o") if t.endswith("/odom")]
    due = range(0, kept.count, 3)
    assert len(odoms) == len(due) * len(bodies) and kept.P is not None
    for j, k in enumerate(due):
        for i, b in enumerate(bodies):
            want = mb.body_odometry(kept.x_hat[k], b, int(kept.stamps[k]), p["world_frame"], b.name, kept.P[k])
            got = odoms[j * len(bodies) + i]
            assert got == want and got.pose.covariance[0] == kept.P[k][b.p_x, b.p_x] > 0
