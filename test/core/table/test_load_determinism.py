"""A table designed in the process and the same table saved and loaded give the same doubles: two
observers over one stream publish bit-identical estimates and envelopes (every z, the paper's bound,
the exact bound, the noise bound), for Kalman and LMI tables at the paper's 12 states and at 40 or
more states (the read's dense eigensolver below 40 states, its other path above)."""

from __future__ import annotations

import numpy as np
import pytest

import switchobs_core as so
from switchobs_core.design.lmi import Designer


def _stream(system, cycle, samples: int, rate: float = 50.0) -> list[tuple[float, int, np.ndarray]]:
    """``samples`` measurements ``(t, channel, y)`` at ``rate`` of a seeded state at rest, with noise."""
    sched = so.PeriodicSchedule(cycle)
    rng = np.random.default_rng(system.n)
    x = np.zeros(system.n)
    x[0::4], x[1::4] = rng.uniform(-5, 5, system.n // 4), rng.uniform(-5, 5, system.n // 4)
    out = []
    for k in range(samples):
        t = k / rate
        ch = sched.channel_at(t)
        H = np.asarray(system.C[ch - 1])
        out.append((t, ch, H @ x + rng.normal(scale=1e-3, size=H.shape[0])))
    return out


def _published(system, table, cycle, stream) -> list[tuple]:
    """Per sample: the estimate and the envelope's numbers, as published."""
    ob = so.SwitchedObserver(system, table, "periodic", [cycle])
    out = []
    for t, ch, y in stream:
        ob.update(t, ch, y)
        e = ob.envelope()
        out.append((ob.x_hat.tobytes(), np.asarray(e.z, dtype=float).tobytes(), e.paper_bound, e.exact_bound,
                    e.noise_bound))
    return out


def _kalman(system, cycle):
    return so.kalman_table(system, [so.design_kalman(system, cycle, 50.0)])


def _lmi(system, cycle):
    return Designer(system, delta=0.99).table([cycle], progress=False)


CASES = {
    "kalman-12": (so.paper_system, lambda: so.Cycle.from_ts(2.0, 0.6), _kalman, 1500),
    "kalman-44": (lambda: so.camera_agents(10), lambda: so.Cycle((0.1,) * 10), _kalman, 1500),
    "lmi-12": (so.paper_system, lambda: so.Cycle.from_ts(2.0, 0.6), _lmi, 600),
    "lmi-40": (lambda: so.camera_agents(9), lambda: so.Cycle((0.5,) * 9), _lmi, 400),
}


@pytest.mark.parametrize("case", sorted(CASES))
def test_designed_and_loaded_publish_the_same_doubles(case, tmp_path):
    make_system, make_cycle, design, samples = CASES[case]
    system, cycle = make_system(), make_cycle()
    designed = design(system, cycle)
    loaded = so.GainTable.load(designed.save(tmp_path / "t.npz"), system=system)
    stream = _stream(system, cycle, samples)
    a, b = _published(system, designed, cycle, stream), _published(system, loaded, cycle, stream)
    moved = [k for k, (u, v) in enumerate(zip(a, b, strict=True)) if u != v]
    assert not moved, f"{len(moved)} of {samples} samples differ, the first at {moved[0]}"


def test_a_designed_gain_is_held_in_c_order():
    """The designed gains are held as a loaded table holds them (C order): the bound sums their
    Frobenius norms in memory order (:func:`~switchobs_core.numerics.rounding.fro_norm`)."""
    design = so.design_kalman(so.paper_system(), so.Cycle.from_ts(2.0, 0.6), 50.0)
    assert design.startup and all(p.K.flags.c_contiguous for p in design.periodic + design.startup)
