"""Numbers printed in the paper (Sec. ``Sec_Sim``), for ``switchobs reproduce`` and tests.

These are the paper's own values, transcribed, never computed here.

Paper labels (``e:...``, ``t:...``) resolve to numbers in ``docs/equations.md``.
"""

from __future__ import annotations

import math

from .exceptions import InvalidArgument
from .validation import as_finite

__all__ = ["MU", "TABLE", "SEQUENCE", "PERIODIC", "PERIODIC_ETA", "DELTA", "D_OFFSETS", "kappa_closed_form"]

#: mu^(1), mu^(2) (Sec. subsec:sim_gain).
MU = (0.6099, 0.5525)
#: The delta that reproduces the paper's eta_min table (the paper never states it; this value reproduces its table).
DELTA = 0.99
#: ((tau, s), (eta_min_1, eta_min_2), (eta_1, eta_2)): the periodic case and Table T:eta_values.
TABLE = (
    ((2.0, 0.6), (1.5, 3.24), (1.6, 3.5)),
    ((4.0, 0.5), (1.18, 1.05), (1.2, 1.1)),
    ((3.0, 0.6), (0.96, 2.12), (1.0, 2.2)),
    ((2.0, 0.4), (3.43, 1.35), (3.5, 1.5)),
)
#: The periodic schedule and its selected rates.
PERIODIC = (2.0, 0.6)
PERIODIC_ETA = (1.6, 3.5)
#: The nonperiodic cycle list (Sec. subsec:sim_params), repeated.
SEQUENCE = ((4.0, 0.5), (3.0, 0.6), (3.0, 0.6), (2.0, 0.4))
#: d_i of the closed form kappa_i(eta) = a + sqrt(1 + a^2), a = eta + d_i (derived for the paper's model).
D_OFFSETS = (0.2, 0.1)


def kappa_closed_form(eta: float, channel: int) -> float:
    """kappa_i(eta) of the paper's model in closed form: an independent oracle."""
    if not isinstance(channel, int) or not 1 <= channel <= len(D_OFFSETS):
        raise InvalidArgument(f"channel must be 1 or 2 (the paper's model); got {channel!r}")
    eta = as_finite(eta, "eta")
    a = eta + D_OFFSETS[channel - 1]
    return a + math.sqrt(1 + a * a)
