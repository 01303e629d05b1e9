"""``switchobs_bag report`` counts the cycles of a system without a channel topic (one topic per
channel, config/cart_pair.yaml) from its input specification, and says "n/a", never 0, when it
cannot know them."""

from __future__ import annotations

import json

import numpy as np
from test_own_system import PERIODIC, RATE, SYSTEM, X0, cart_table  # noqa: F401  (cart_table: the fixture)

import msg_bridge as mb
from switchobs_core.model.scenarios import load_system
from switchobs_ros.bag.cli import main as bag_main
from switchobs_ros.bag.estimate import estimate, estimator_params
from switchobs_ros.bag.generate import GenerateConfig, generate
from switchobs_ros.bag.report import load_report, summary_table


def test_cycles_from_the_per_channel_topics(tmp_path, cart_table, capsys):  # noqa: F811
    generate(tmp_path / "in", GenerateConfig(system=SYSTEM, schedule="periodic:2,0.6", duration=10.0, rate=RATE,
                                             initial_state=X0), "mcap")
    params = estimator_params(overrides={"system": SYSTEM, "gain_table": cart_table, **PERIODIC,
                                         "e0": float(np.linalg.norm(X0)) * 1.01})
    estimate(tmp_path / "in", params, out=tmp_path / "est")

    blind = load_report(tmp_path / "est")             # no channel topic in the bag, no specification
    (p,) = blind.passes
    assert p.cycle_ends is None and p.cycle_err == []
    text = summary_table(blind)
    assert "Cycles: n/a" in text and "| n/a | n/a | n/a |" in text

    specs = mb.load_inputs(SYSTEM, load_system(SYSTEM))
    (p,) = load_report(tmp_path / "est", inputs=specs).passes
    # the schedule (2 s, 0.6) from the first sample: channel 1 starts again at 2, 4, ... s
    want = [2.0 * k for k in range(1, int(p.t[-1] / 2.0 + 1e-9) + 1)]
    np.testing.assert_allclose(p.cycle_ends, want, atol=0.5 / RATE)
    assert len(p.cycle_err) == len(want) and len(p.contraction) == len(want) - 1
    assert all(0 < c < 1 for c in p.contraction), p.contraction        # the error contracts every cycle

    capsys.readouterr()
    assert bag_main(["report", str(tmp_path / "est"), "-o", str(tmp_path / "r.png"), "--system", SYSTEM,
                     "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["passes"][0]["cycles"] == len(want)
    assert bag_main(["report", str(tmp_path / "est"), "-o", str(tmp_path / "r2.png"), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["passes"][0]["cycles"] is None
