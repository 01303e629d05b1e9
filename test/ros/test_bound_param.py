"""The estimator's ``bound`` parameter: the observer gets the form asked for, a value it does not know
or a table it does not apply to is refused at start-up with the parameter named."""

from __future__ import annotations

import pytest

from switchobs_core.design.kalman import design_kalman
from switchobs_core.model.scenarios import load_system
from switchobs_core.model.schedule import Cycle
from switchobs_core.table.gains import kalman_table
from switchobs_ros.bag.estimate import estimator_params
from switchobs_ros.config import EstimatorConfig
from switchobs_ros.params import ConfigError
from switchobs_ros.pipeline import EstimatorPipeline


def test_the_bound_parameter_reaches_the_observer(tmp_path, paper_tables):
    sys_ = load_system("paper")
    ktable = str(kalman_table(sys_, [design_kalman(sys_, Cycle.from_ts(2.0, 0.6), 50.0)]).save(tmp_path / "k.json"))
    pl = EstimatorPipeline.from_params(estimator_params(overrides={"gain_table": ktable, "bound": "phase"}))
    assert pl.observer.bound_form == "phase" and pl.observer.rounding.phase is not None
    pl = EstimatorPipeline.from_params(estimator_params(overrides={"gain_table": ktable}))
    assert pl.observer.bound_form == "ellipsoid" and pl.observer.rounding.phase is None
    with pytest.raises(ConfigError, match="bound 'phase' needs a Kalman table"):
        EstimatorPipeline.from_params(estimator_params(overrides={"gain_table": paper_tables["periodic"],
                                                                  "bound": "phase"}))
    with pytest.raises(ConfigError, match="parameter 'bound' must be one of ellipsoid, phase"):
        EstimatorConfig.from_values({"bound": "ball"})
