"""The paper's gain designs as data: one verified LMI gain per channel and cycle (Section 7).

A :class:`CycleDesign` holds, for one cycle (or for a residence-time box, the robust
design), one verified gain per channel with its eta, kappa, mu and the paper's cycle
factor f_ii = kappa_i exp(mu_i (tau - h_i) - eta_i h_i) (e:f11_le_delta_main). The gain table
(:mod:`switchobs_core.table.gains`) stores them;
:mod:`switchobs_core.certificate.paper_check` checks the paper's condition on an observed cycle.

Paper labels (``e:...``, ``t:...``) resolve to numbers in ``docs/equations.md``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ..certificate import cycle_factor
from ..certificate.paper_check import CertifyCheck, certifies
from ..model.schedule import Cycle

__all__ = ["ChannelGain", "CycleDesign"]


@dataclass(frozen=True)
class ChannelGain:
    """The verified gain of one channel in one design.

    ``active``/``inactive`` are the durations the design was made for (h_i and
    tau - h_i; for a robust design the worst case of the box).
    """

    eta_min: float | None
    eta: float
    kappa: float
    kappa_star: float
    mu: float
    active: float
    inactive: float
    f: float
    eta_verified: float
    abscissa: float
    L_o: np.ndarray
    L: np.ndarray
    P: np.ndarray

    def factor(self, active: float, inactive: float) -> float:
        """The paper's cycle factor kappa exp(mu * inactive - eta * active) for other durations."""
        return cycle_factor(self.kappa, self.mu, self.eta, active, inactive)

    def to_dict(self) -> dict[str, Any]:
        d = {
            k: getattr(self, k)
            for k in (
                "eta_min",
                "eta",
                "kappa",
                "kappa_star",
                "mu",
                "active",
                "inactive",
                "f",
                "eta_verified",
                "abscissa",
            )
        }
        d.update(L_o=self.L_o.tolist(), L=self.L.tolist(), P=self.P.tolist())
        return d

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> ChannelGain:
        kw = {k: (None if d[k] is None else float(d[k])) for k in ("eta_min",)}
        kw.update(
            {
                k: float(d[k])
                for k in ("eta", "kappa", "kappa_star", "mu", "active", "inactive", "f", "eta_verified", "abscissa")
            }
        )
        kw.update({k: np.array(d[k], dtype=float) for k in ("L_o", "L", "P")})
        return cls(**kw)


@dataclass(frozen=True)
class CycleDesign:
    """One gain set: per channel a verified gain for a cycle (or a residence-time box)."""

    kind: str
    cycle: Cycle | None
    h_bounds: tuple[float, float] | None
    delta: tuple[float, ...]
    channels: tuple[ChannelGain, ...]

    @property
    def N(self) -> int:
        return len(self.channels)

    @property
    def L(self) -> tuple[np.ndarray, ...]:
        """Embedded gains L_i = T_i [L_o^(i); 0] (e:L_original), n x p_i."""
        return tuple(c.L for c in self.channels)

    @property
    def eta(self) -> tuple[float, ...]:
        return tuple(c.eta for c in self.channels)

    @property
    def eta_min(self) -> tuple[float | None, ...]:
        return tuple(c.eta_min for c in self.channels)

    @property
    def kappa(self) -> tuple[float, ...]:
        return tuple(c.kappa for c in self.channels)

    @property
    def mu(self) -> tuple[float, ...]:
        return tuple(c.mu for c in self.channels)

    @property
    def f(self) -> tuple[float, ...]:
        """The paper's cycle factors f_ii at the design durations."""
        return tuple(c.f for c in self.channels)

    @property
    def certified(self) -> bool:
        """Whether f_ii <= delta_i for all i (the paper's condition; not a guarantee, see
        :mod:`switchobs_core.certificate`)."""
        return all(f <= d for f, d in zip(self.f, self.delta))

    def label(self) -> str:
        if self.kind == "robust" and self.h_bounds is not None:
            return f"robust h in [{self.h_bounds[0]:g}, {self.h_bounds[1]:g}]"
        return self.cycle.label() if self.cycle is not None else self.kind

    def certifies(self, observed: Cycle) -> CertifyCheck:
        """Check the paper's cycle condition for an observed cycle with these gains
        (:func:`switchobs_core.certificate.paper_check.certifies`)."""
        return certifies(self, observed)

    def to_dict(self) -> dict[str, Any]:
        return {
            "kind": self.kind,
            "cycle": None if self.cycle is None else self.cycle.to_dict(),
            "h_bounds": None if self.h_bounds is None else list(self.h_bounds),
            "delta": list(self.delta),
            "channels": [c.to_dict() for c in self.channels],
        }

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> CycleDesign:
        return cls(
            kind=str(d["kind"]),
            cycle=None if d["cycle"] is None else Cycle(d["cycle"]["h"], d["cycle"].get("dead_time", 0.0)),
            h_bounds=None if d["h_bounds"] is None else (float(d["h_bounds"][0]), float(d["h_bounds"][1])),
            delta=tuple(float(x) for x in d["delta"]),
            channels=tuple(ChannelGain.from_dict(c) for c in d["channels"]),
        )
