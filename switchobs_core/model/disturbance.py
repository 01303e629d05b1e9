"""A declared bounded unknown input: ``x' = A x + B u + B_w w`` with ``|w_j| <= max_j``.

Beyond the paper: its plant (e:system) follows ``x' = A x + B u`` exactly. Real bodies accelerate;
a declared disturbance says by how much, and the observer's ``noise_bound`` then holds for every
``w`` inside the box (:mod:`switchobs_core.numerics.disturbance_reach`: the reachable set of one
step, added to the error bound of every step).

YAML (the ``disturbance:`` mapping of a system file)::

    disturbance:
      B_w: [[0, 0], [0, 0], [1, 0], [0, 1]]     # n x q (optional for systems with velocity states)
      max: 0.2                                  # one bound for every w_j, or q bounds

Without ``B_w``, the velocity states (labels ending in ``v_x``, ``v_y``, ``v_z``, as the built-in
scenarios of :mod:`switchobs_core.model.scenarios` name them) each get a unit acceleration: one
column ``e_i`` per velocity state ``i``. A built-in scenario declares ``B_w`` that way and
``max = 0`` (no disturbance) until a bound is given (the nodes' and bag tools' ``disturbance.max``).

The Kalman design's process noise follows the same ``B_w``: ``Q_c = B_w diag(max^2) B_w'`` as the
spectral density of the continuous-time white noise (:meth:`Disturbance.intensity`; the design
discretises it exactly, :mod:`switchobs_core.design.kalman`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..exceptions import InvalidSystem
from ..loading import as_number

__all__ = ["Disturbance", "DISTURBANCE_KEYS", "MAX_DISTURBANCE", "velocity_inputs", "parse_max"]

#: Keys of the ``disturbance:`` mapping.
DISTURBANCE_KEYS = ("B_w", "max")
#: Largest accepted bound of one input (its square enters a covariance, whose entries stay below
#: :data:`~switchobs_core.model.noise.MAX_ABS_ENTRY`).
MAX_DISTURBANCE = 1e49
#: State label endings that name a velocity (the built-in scenarios' ``<body>.v_x``).
VELOCITY_SUFFIXES = ("v_x", "v_y", "v_z")


def velocity_inputs(system: Any) -> np.ndarray:
    """``B_w`` of unit accelerations: one column ``e_i`` per velocity state of ``system`` (labels
    ending in ``v_x``, ``v_y``, ``v_z``); an ``(n, 0)`` matrix when it has none."""
    n = int(system.n)
    idx = [i for i, lab in enumerate(system.state_labels) if str(lab).endswith(VELOCITY_SUFFIXES)]
    return np.eye(n)[:, idx]


def parse_max(value: Any, q: int, where: str) -> np.ndarray:
    """``max`` as ``q`` bounds: one number for all, or ``q`` numbers, each finite and >= 0."""
    if isinstance(value, np.ndarray):
        value = value.tolist()
    vals = list(value) if isinstance(value, (list, tuple)) else [value]
    nums = [as_number(v, where, exc=InvalidSystem, finite=False) for v in vals]
    bad = [v for v in nums if not (math.isfinite(v) and 0.0 <= v <= MAX_DISTURBANCE)]
    if bad:
        raise InvalidSystem(f"{where} must hold finite bounds in [0, {MAX_DISTURBANCE:g}]; got {bad[0]!r}")
    if len(nums) == 1:
        return np.full(q, nums[0])
    if len(nums) != q:
        raise InvalidSystem(f"{where} needs one number or q = {q} numbers (one per column of B_w); got {len(nums)}")
    return np.array(nums, dtype=float)


@dataclass(frozen=True, eq=False)
class Disturbance:
    """``B_w`` (n x q) and the bounds ``max`` (q) of ``|w_j| <= max_j`` (module docstring).

    ``Disturbance(B_w, w_max)``; :meth:`from_mapping` reads the YAML form, :meth:`with_max`
    replaces the bounds (``disturbance.max``).
    """

    B_w: np.ndarray
    w_max: np.ndarray

    def __init__(self, B_w: Any, w_max: Any, *, where: str = "disturbance max") -> None:
        B = np.array(B_w, dtype=float)
        if B.ndim != 2 or not np.all(np.isfinite(B)):
            raise InvalidSystem(f"disturbance B_w must be a finite n x q matrix; got shape {B.shape}")
        m = parse_max(w_max, B.shape[1], where)
        for M in (B, m):
            M.setflags(write=False)
        object.__setattr__(self, "B_w", B)
        object.__setattr__(self, "w_max", m)

    @classmethod
    def from_mapping(cls, spec: Mapping[str, Any] | None, system: Any, *, source: str = "disturbance") -> Disturbance:
        """The ``disturbance:`` mapping (None: the velocity states' unit accelerations, ``max = 0``)."""
        spec = {} if spec is None else spec
        if not isinstance(spec, Mapping):
            raise InvalidSystem(f"{source} must be a mapping with keys {', '.join(DISTURBANCE_KEYS)}; got {spec!r:.60}")
        unknown = sorted(map(str, set(spec) - set(DISTURBANCE_KEYS)))
        if unknown:
            raise InvalidSystem(f"{source}: unknown key(s) {unknown}; allowed: {', '.join(DISTURBANCE_KEYS)}")
        B = velocity_inputs(system) if spec.get("B_w") is None else np.array(spec["B_w"], dtype=float)
        if B.ndim == 1 and B.size == system.n:
            B = B.reshape(-1, 1)
        if B.ndim != 2 or B.shape[0] != system.n:
            raise InvalidSystem(f"{source}: B_w must be an n x q matrix with n = {system.n} rows; got shape {B.shape}")
        try:
            return cls(B, spec.get("max", 0.0))
        except InvalidSystem as err:
            raise InvalidSystem(f"{source}: {err}") from None

    def with_max(self, w_max: Any, where: str = "disturbance.max") -> Disturbance:
        """The same ``B_w`` with the bounds ``w_max`` (one number or q; ``where`` names them in errors)."""
        return Disturbance(self.B_w, w_max, where=where)

    @property
    def q(self) -> int:
        """Number of unknown inputs."""
        return self.B_w.shape[1]

    @property
    def active(self) -> bool:
        """Whether some input may be nonzero (a column and a bound > 0)."""
        return self.q > 0 and bool(np.any(self.w_max > 0.0))

    def intensity(self) -> np.ndarray:
        """``Q_c = B_w diag(max^2) B_w'``: the Kalman design's process-noise spectral density."""
        Q = (self.B_w * (self.w_max ** 2)[None, :]) @ self.B_w.T
        return 0.5 * (Q + Q.T)

    def describe(self) -> str:
        """One line: q and the bounds' range."""
        if not self.active:
            return "disturbance: none declared"
        return f"disturbance: q = {self.q} inputs, |w_j| <= {self.w_max.min():g}..{self.w_max.max():g}"
