"""``switchobs_bag estimate`` writes its outputs as the estimates come: the CSV and the bag of a run
that keeps nothing in memory (``keep=False``, what the command runs) are those of a run that keeps
every estimate, and its result holds only their number."""

from __future__ import annotations

import importlib
import json

import numpy as np
import pytest

import msg_bridge as mb
from switchobs_ros.bag import cdr
from switchobs_ros.bag.cli import main as bag_main
from switchobs_ros.bag.estimate import estimate, estimator_params, write_csv
from switchobs_ros.bag.generate import GenerateConfig, generate
from switchobs_ros.bag.io import BagIn, deserialize


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
