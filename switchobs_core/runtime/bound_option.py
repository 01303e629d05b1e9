"""The observer's ``bound`` option: the form of its rigorous bounds.

``"ellipsoid"`` (default)
    the ellipsoids of :class:`~switchobs_core.bounds.rigorous.RoundingBound`, stepped every sample
    (``M S M'`` and its allowances) and read by an eigenvalue problem or amortised
    (:mod:`switchobs_core.bounds.read`).
``"phase"``
    Kalman tables only: on the table's periodic grid, scalars in a norm fixed per phase
    (:mod:`switchobs_core.bounds.phase_bound`), O(1) per sample after the residual's O(n) norms; the
    ellipsoids everywhere else (the start-up, departures, restarts), converted both ways with
    proofs; stamps jittered within the table's ``dt_tol`` stay on the scalars. Its constants are
    proved when the observer is built (a progress line on standard error when that takes seconds:
    about 8 s at n = 132), from
    the table's own maps: nothing is stored in the table, and a table file of any version can use
    it. Measured (``bench/bench_scale.py --cost --steady``, bench/RESULTS.md): the node pattern
    (update and ``envelope()``) at 0.84x / 0.54x / 0.04x a reference Kalman filter at n = 12 / 36 /
    132 (the ellipsoids: 2.55x / 2.31x / 0.41x); the exact bound 2.8x / 3.1x / 7.6x the ellipsoid's,
    the noise bound 6x / 22x / 27x. It covers the noise set of a declared ``noise_max`` and a
    declared clock tolerance; a declared disturbance is refused.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..bounds.phase_bound import PhaseBound
from ..exceptions import InvalidArgument

__all__ = ["BOUND_FORMS", "bound_form"]

#: The values of the ``bound`` option.
BOUND_FORMS = ("ellipsoid", "phase")


def bound_form(bound: str, family: str, gains: Any, rigorous: Any, disturbance: Any, scale: np.ndarray) -> str:
    """Check the ``bound`` option and, for ``"phase"``, attach a
    :class:`~switchobs_core.bounds.phase_bound.PhaseBound` to the rigorous bound ``rigorous``
    (a :class:`~switchobs_core.bounds.rigorous.RoundingBound`); returns the option.

    Raises
    ------
    InvalidArgument
        An unknown form, or ``"phase"`` where it does not apply: not a Kalman table in use, no rigorous
        bound kept (``rounding_bound`` off or measurement hold), a declared disturbance, a table
        whose periodic phases hold partial rows or whose constants cannot be proved.
    """
    if bound not in BOUND_FORMS:
        raise InvalidArgument(f"bound must be one of {', '.join(BOUND_FORMS)}; got {bound!r}")
    if bound == "ellipsoid":
        return bound
    if family != "kalman":
        raise InvalidArgument(f"bound 'phase' needs a Kalman table in use (family 'kalman'); the family is {family!r}")
    if rigorous is None:
        raise InvalidArgument("bound 'phase' needs the rigorous bound (rounding_bound on, innovation hold)")
    if disturbance is not None and getattr(disturbance, "active", True):
        raise InvalidArgument("bound 'phase' does not cover a declared disturbance; use bound 'ellipsoid'")
    try:
        rigorous.phase = PhaseBound(gains.periodic_maps(), scale, rigorous.noise_max is not None)
    except ValueError as err:
        raise InvalidArgument(f"bound 'phase': {err}; use bound 'ellipsoid'") from None
    return bound
