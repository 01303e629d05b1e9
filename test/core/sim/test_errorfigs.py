"""The simulate figure shows only what applies, beside the curves, and the simulate table lists
every cycle of the run: the paper's envelopes only for its LMI gains; one bound, the one the run
can call guaranteed (none with noise and no declared noise bound, the bounded-noise bound with
one); legends outside the panels; a run of whole cycles reports each of them."""

from __future__ import annotations

import numpy as np
import pytest

from switchobs_core.design.kalman import design_kalman
from switchobs_core.model.schedule import Cycle, PeriodicSchedule
from switchobs_core.sim.errorfigs import error_figure, figure_curves
from switchobs_core.sim.simulate import simulate
from switchobs_core.table.gains import kalman_table

C = Cycle.from_ts(2.0, 0.6)


@pytest.fixture(scope="module")
def ktable(paper):
    return kalman_table(paper, [design_kalman(paper, [C], 50.0)])


def _run(paper, table, t_end, **kw):
    rng = np.random.default_rng(3)
    x0 = rng.standard_normal(paper.n)
    return simulate(paper, table, PeriodicSchedule(C), x0, x0 + 0.1 * rng.standard_normal(paper.n), t_end, **kw)


def _labels(spec, key):
    return [lab for lab, _, _ in spec[key]]


def test_lmi_draws_the_paper_envelopes_and_the_exact_bound(paper, paper_table):
    res = _run(paper, paper_table, 4.0)
    spec = figure_curves(res)
    assert sum("paper's envelope" in lab for lab in _labels(spec, "top")) == 2
    assert any("paper's bound" in lab for lab in _labels(spec, "middle"))
    (bound,) = [v for lab, v, _ in spec["middle"] if lab.startswith("guaranteed bound")]
    assert bound is res.exact_bound and spec["note"] == ""
    assert np.all(res.error_norm <= bound * (1 + 1e-9))


def test_kalman_noisy_without_declared_bound_draws_no_bound_and_no_paper_envelope(paper, ktable):
    res = _run(paper, ktable, 4.0, rate=50.0, noise_std=0.01, seed=1)
    spec = figure_curves(res)
    every = " ".join(_labels(spec, "top") + _labels(spec, "middle"))
    assert "paper" not in every and "z_" not in every and "bound" not in every
    assert len(spec["middle"]) == 1                              # the error alone
    assert "no bound drawn" in spec["note"] and "LMI gains only" in spec["note"]
    # what was drawn before: the noise-free bound, decades under the noisy error
    assert np.median(res.error_norm[-50:] / res.exact_bound[-50:]) > 1e3


def test_declared_noise_bound_is_the_bound_drawn_and_holds(paper, ktable):
    res = _run(paper, ktable, 4.0, rate=50.0, noise_std=0.001, noise_max=0.002, seed=1)
    spec = figure_curves(res)
    (bound,) = [v for lab, v, _ in spec["middle"] if lab.startswith("guaranteed bound")]
    assert bound is res.noise_bound
    assert np.all(res.error_norm <= bound * (1 + 1e-9))
    assert res.exact_bound is not bound and not any(v is res.exact_bound for _, v, _ in spec["middle"])


@pytest.mark.parametrize("which", ["lmi", "kalman"])
def test_legends_sit_beside_the_panels(paper, paper_table, ktable, which):
    res = _run(paper, paper_table, 4.0) if which == "lmi" else _run(paper, ktable, 4.0, rate=50.0)
    fig = error_figure(res, "t")
    fig.canvas.draw()
    axes = [a for a in fig.axes if a.get_legend() is not None]
    assert len(axes) == 2
    for a in axes:
        leg, box = a.get_legend().get_window_extent(), a.get_window_extent()
        assert leg.x0 >= box.x1 - 1e-6, (leg, box)            # right of the panel, not on the curves
        texts = [t.get_text() for t in a.get_legend().get_texts()]
        assert len(texts) == len(a.get_lines())                 # every drawn curve named, nothing else


@pytest.mark.parametrize("t_end, ends", [(6.0, [2.0, 4.0, 6.0]), (5.0, [2.0, 4.0]), (6.5, [2.0, 4.0, 6.0])])
def test_cycle_ends_include_a_cycle_that_ends_with_the_run(paper, paper_table, ktable, t_end, ends):
    cont = _run(paper, paper_table, t_end)
    np.testing.assert_allclose(cont.cycle_ends, ends, rtol=0, atol=1e-9)
    assert cont.summary()["cycles"] == len(ends)
    sampled = _run(paper, ktable, t_end, rate=50.0)
    np.testing.assert_allclose(sampled.cycle_ends, ends, rtol=0, atol=1e-9)
