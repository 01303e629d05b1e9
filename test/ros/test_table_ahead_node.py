"""The estimator's configuration reads ``gain_table`` in a worker thread while it builds the system:
the pipeline gets the table a load in place gives, a bad table is still refused in one line (exit
code 2), with the message of a load in place, and a refused configuration leaves no thread reading."""

from __future__ import annotations

import threading

import pytest
from refusals import assert_refused, node_main

from switchobs_core.table.gains import GainTable
from switchobs_ros.config import EstimatorConfig
from switchobs_ros.core_config import load_or_design_table
from switchobs_ros.params import ConfigError
from switchobs_ros.pipeline import EstimatorPipeline
from tools.launch import ros_args


def _readers() -> list[threading.Thread]:
    return [t for t in threading.enumerate() if t.name == "table-read-ahead"]


@pytest.mark.parametrize("kind", ["json", "npz"])
def test_pipeline_takes_the_table_read_ahead(paper_tables, tmp_path, kind):
    """The configuration starts the read; the pipeline's table is the one ``GainTable.load`` gives
    (the same JSON text: every number) and its observer starts from the same estimate and bound."""
    path = paper_tables["periodic"]
    if kind == "npz":
        path = str(GainTable.load(path).save(tmp_path / "periodic.npz"))
    conf = EstimatorConfig.from_values({"gain_table": path})
    assert conf.table_ahead is not None and conf.table_ahead.path.samefile(path)
    pl = EstimatorPipeline.from_params(conf)
    assert pl.table.to_json() == GainTable.load(path, system=conf.system).to_json()
    again = EstimatorPipeline.from_params(conf)         # taken once: a second pipeline reads the file itself
    assert again.table is not pl.table and again.table.to_json() == pl.table.to_json()
    assert (pl.observer.x_hat == again.observer.x_hat).all()
    assert not _readers()


def test_bad_table_refused_in_one_line(paper_tables, tmp_path):
    """A truncated .npz: the node refuses it in one line with exit code 2, and the configuration's
    refusal is the one a load in place gives."""
    data = GainTable.load(paper_tables["periodic"]).save(tmp_path / "good.npz").read_bytes()
    bad = tmp_path / "truncated.npz"
    bad.write_bytes(data[: len(data) // 2])
    res = node_main("estimator", ros_args(params={"gain_table": str(bad)}))
    assert_refused(res, "estimator: error:", "gain_table", "truncated.npz", "truncated", code=2)
    conf = EstimatorConfig.from_values({"gain_table": str(bad)})
    with pytest.raises(ConfigError) as ahead:
        EstimatorPipeline.from_params(conf)
    with pytest.raises(ConfigError) as in_place:
        load_or_design_table(str(bad), conf["gain_table_cache_dir"], conf.system, conf.mode, list(conf.cycles),
                             conf.robust, conf["delta"], print)
    assert str(ahead.value) == str(in_place.value) and "\n" not in str(ahead.value)


def test_refused_configuration_leaves_no_reader(paper_tables):
    """A parameter refused after the read started (a schedule that does not fit the system): the
    refusal is raised and the worker has ended."""
    with pytest.raises(ConfigError, match="schedule"):
        EstimatorConfig.from_values({"gain_table": paper_tables["periodic"], "schedule.mode": "periodic",
                                     "schedule.h": [1.0, 2.0, 3.0]})
    assert not _readers()
