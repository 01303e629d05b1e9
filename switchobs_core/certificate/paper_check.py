"""The paper's cycle condition on an observed cycle (e:f11_le_delta_main).

``certifies(design, observed)``: with the design's gains, is ``f_ii(observed) <= delta_i`` for
every channel (the paper's factor ``kappa_i exp(mu_i (tau - h_i) - eta_i h_i)`` for the observed
durations)? Also reports the simpler sufficient rule (observed active times no shorter and
inactive times no longer than designed). The paper's condition, not a guarantee: see
:mod:`switchobs_core.certificate`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from ..exceptions import InvalidArgument
from ..model.schedule import Cycle

__all__ = ["CertifyCheck", "certifies"]


@dataclass(frozen=True)
class CertifyCheck:
    """Whether a design's gains satisfy the paper's cycle condition on an observed cycle.

    Attributes
    ----------
    ok : bool
        f_ii(observed) <= delta_i for every channel: the paper's condition
        e:f11_le_delta_main holds for the observed durations with these gains.
    dominated : bool
        The simpler sufficient rule: every observed active time >= the designed one and
        every observed inactive time <= the designed one (for mu_i >= 0; reversed in the
        inactive time for mu_i < 0).
    f : tuple of float
        f_ii for the observed durations.
    """

    ok: bool
    dominated: bool
    f: tuple[float, ...]
    delta: tuple[float, ...]


def certifies(design: Any, observed: Cycle) -> CertifyCheck:
    """Check the paper's cycle condition for an observed cycle with ``design``'s gains (a CycleDesign)."""
    if not isinstance(observed, Cycle):
        raise InvalidArgument(f"observed must be a Cycle; got {observed!r}")
    if observed.N != design.N:
        raise InvalidArgument(f"observed cycle has {observed.N} channels; the design has {design.N}")
    fs, dom = [], True
    for i, c in enumerate(design.channels):
        act, ina = observed.active(i + 1), observed.inactive(i + 1)
        fs.append(c.factor(act, ina))
        ok_in = ina <= c.inactive * (1 + 1e-12) if c.mu >= 0 else ina >= c.inactive * (1 - 1e-12)
        dom &= act >= c.active * (1 - 1e-12) and ok_in
    ok = all(f <= d for f, d in zip(fs, design.delta))
    return CertifyCheck(ok=ok, dominated=bool(dom), f=tuple(fs), delta=design.delta)
