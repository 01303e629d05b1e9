"""Gain tables: the designs of :mod:`switchobs_core.design.lmi`, and their file.

A :class:`CycleDesign` holds, for one cycle (or for a residence-time box, the robust
design), one verified gain per channel with its eta, kappa, mu and the paper's cycle
factor f_ii = kappa_i exp(mu_i (tau - h_i) - eta_i h_i) (e:f11_le_delta_main).

A table holds one gain *family* (``family``): ``"lmi"``, the paper's LMI gains per cycle
(:mod:`switchobs_core.design.lmi`), or ``"kalman"``, offline periodic Kalman gains per sample phase
of a (super-)cycle at a nominal rate (:mod:`switchobs_core.design.kalman`). The observer, the exact
bound and the certificates only use the error maps the observer applies, so they serve both.

File format (JSON, ``format = "switchobs-gain-table"``, ``format_version = 2``; version 1
files, which are LMI tables without the two last keys, still load)::

    {
      "format": "switchobs-gain-table", "format_version": 2,
      "software_version": "0.1.0",
      "system": {"name", "fingerprint", "n", "p": [...], "N"},
      "delta": [delta_1, ..., delta_N],
      "settings": {"margin": {"kind", "value"}, "solver", "theta_slack", "rank_rtol"},
      "channels": [{"r", "mu", "T_o": [[...]], "kappa_curve": {"eta": [...], "kappa": [...]}}],
      "designs": [design, ...],          # kind "cycle"
      "robust": design | null,           # kind "robust"
      "family": "lmi" | "kalman",
      "kalman": [kalman_design, ...],    # KalmanDesign.to_dict(): rate, cycles, noise model,
                                         # periodic and start-up phases (P^-, K per sample)
      "payload_sha256": "..."            # sha256 of the canonical JSON of everything else
    }

    design = {"kind", "cycle": {"tau", "h"} | null, "h_bounds": [h_min, h_max] | null,
              "delta": [...], "channels": [{"eta_min", "eta", "kappa", "kappa_star", "mu",
              "active", "inactive", "f", "eta_verified", "abscissa",
              "L_o": [[...]], "L": [[...]], "P": [[...]]}]}

Floats are written with Python's shortest round-trip repr, so a table round-trips bit
for bit. The file is written atomically (temporary file in the same folder, fsync,
rename). Loading checks the format and version, the checksum, that every number is
finite, and (given a system) the system fingerprint and that the stored observable
bases T_o are the system's.

Lookup tolerance: :meth:`GainTable.lookup` matches a cycle when every active time agrees
within ``atol + rtol * tau`` (defaults ``schedule.CYCLE_RTOL = 1e-6``,
``schedule.CYCLE_ATOL = 1e-9`` s).

Where the parts live: the LMI result types in :mod:`switchobs_core.table.lmi`, the paper's check on an
observed cycle in :mod:`switchobs_core.certificate.paper_check`, the file's reading and writing in
:mod:`switchobs_core.table.io`, its layout check in :mod:`switchobs_core.table.schema`; this module
holds the table itself (lookup, the Kalman designs it stores, the system check) and re-exports the names it always had.

Paper labels (``e:...``, ``t:...``) resolve to numbers in ``docs/equations.md``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from .._version import __version__
from ..certificate.paper_check import CertifyCheck
from ..exceptions import GainTableError, InvalidArgument, SwitchobsError
from ..families import TABLE_FAMILIES  # noqa: F401  (kept importable from here)
from ..model.schedule import CYCLE_ATOL, CYCLE_RTOL, Cycle
from . import io as table_io
from .io import FORMAT, FORMAT_VERSION, READABLE_VERSIONS  # noqa: F401  (kept importable from here)
from .kalman import KalmanDesign
from .lmi import ChannelGain, CycleDesign

if TYPE_CHECKING:
    from ..model.system import LTISystem

__all__ = ["ChannelGain", "CycleDesign", "CertifyCheck", "GainTable", "FORMAT", "FORMAT_VERSION", "kalman_table"]


@dataclass
class GainTable:
    """Designs for one system, with what is needed to check they belong to it."""

    system_name: str
    fingerprint: str
    n: int
    p: tuple[int, ...]
    delta: tuple[float, ...]
    settings: dict[str, Any]
    channels: list[dict[str, Any]]
    designs: list[CycleDesign] = field(default_factory=list)
    robust: CycleDesign | None = None
    software_version: str = __version__
    family: str = "lmi"
    kalman: list[dict[str, Any]] = field(default_factory=list)
    _kalman_cache: dict = field(default_factory=dict, init=False, repr=False, compare=False)

    @property
    def N(self) -> int:
        return len(self.p)

    def lookup(self, cycle: Cycle, *, rtol: float = CYCLE_RTOL, atol: float = CYCLE_ATOL) -> CycleDesign:
        """The stored design of ``cycle`` (tolerance in the module docstring)."""
        if not isinstance(cycle, Cycle):
            raise GainTableError(f"cycle must be a Cycle (e.g. Cycle.from_ts(2.0, 0.6)); got {cycle!r}")
        for d in self.designs:
            if d.cycle is not None and d.cycle.matches(cycle, rtol=rtol, atol=atol):
                return d
        have = ", ".join(d.label() for d in self.designs) or "none"
        raise GainTableError(f"no design for cycle {cycle.label()} in the table (designed cycles: {have})")

    def stored_kalman(self, d: dict, system: LTISystem) -> KalmanDesign:
        """``KalmanDesign.from_dict(d, system)`` of the stored design ``d`` (an entry of :attr:`kalman`),
        built once per design and system object: the table check at load and the observer's family
        read the same one (3 200 phases at 32 agents: 25-35 ms a build)."""
        key = (id(d), id(system))       # both kept alive by the cached design (kd.system) and the table
        kd = self._kalman_cache.get(key)
        if kd is None:
            kd = self._kalman_cache[key] = KalmanDesign.from_dict(d, system)
        return kd

    def kalman_design(self, cycles: Sequence[Cycle], system: LTISystem, *, rtol: float = CYCLE_RTOL,
                      atol: float = CYCLE_ATOL) -> KalmanDesign:
        """The stored Kalman design of the cycle sequence ``cycles`` (one cycle: periodic).

        Matches the sequence in order, each cycle within the tolerance of :meth:`lookup`.
        ``system`` rebuilds the design (its fingerprint is checked).
        """
        cycles = [cycles] if isinstance(cycles, Cycle) else list(cycles)
        for d in self.kalman:
            stored = [Cycle(h, d.get("dead_time", 0.0)) for h in d.get("cycles", [])]
            if len(stored) == len(cycles) and all(a.matches(b, rtol=rtol, atol=atol) for a, b in zip(stored, cycles)):
                try:
                    return self.stored_kalman(d, system)
                except SwitchobsError as err:
                    raise GainTableError(f"gain table: stored Kalman design unusable: {err}") from None
        have = "; ".join(", ".join(Cycle(h, d.get("dead_time", 0.0)).label() for h in d.get("cycles", []))
                         for d in self.kalman) or "none"
        want = ", ".join(c.label() for c in cycles)
        raise GainTableError(f"no Kalman design for the cycle sequence {want} in the table (designed: {have}); "
                             "design it with `switchobs design ... --gains kalman`")

    def find(self, cycle: Cycle) -> CycleDesign | None:
        """Like :meth:`lookup` but ``None`` when absent."""
        try:
            return self.lookup(cycle)
        except GainTableError:
            return None

    def certifying(self, observed: Cycle) -> list[CycleDesign]:
        """All stored designs (robust included) whose gains satisfy the paper's condition on ``observed``."""
        cands = self.designs + ([self.robust] if self.robust is not None else [])
        return [d for d in cands if d.certifies(observed).ok]

    def T_o(self, channel: int) -> np.ndarray:
        """Stored observable basis T_o of a channel (1-based)."""
        return np.array(self.channels[channel - 1]["T_o"], dtype=float)

    def kappa_curve(self, channel: int) -> tuple[np.ndarray, np.ndarray]:
        """Stored (eta, kappa) samples of a channel's kappa curve."""
        if not isinstance(channel, int) or not 1 <= channel <= len(self.channels):
            raise GainTableError(f"channel must be in 1..{len(self.channels)}; got {channel!r}")
        kc = self.channels[channel - 1]["kappa_curve"]
        return np.array(kc["eta"], float), np.array(kc["kappa"], float)

    # ------------------------------------------------------------------ file (switchobs_core.table.io)
    def _payload(self) -> dict[str, Any]:
        return table_io.table_payload(self)

    @staticmethod
    def _digest(payload: dict[str, Any]) -> str:
        return table_io.digest(payload)

    def to_json(self) -> str:
        """The file's text."""
        return table_io.to_json(self)

    def save(self, path: str | Path) -> Path:
        """Write the table atomically (:func:`switchobs_core.table.io.save`): JSON, or the binary
        container of :mod:`switchobs_core.table.container` when the name ends in ``.npz``."""
        return table_io.save(self, path)

    @classmethod
    def from_json(cls, text: str, *, source: str = "<text>", system: LTISystem | None = None) -> GainTable:
        """Parse and check a table (:mod:`switchobs_core.table.io`); ``system`` adds the fingerprint check."""
        return table_io.from_json(cls, text, source=source, system=system)

    @classmethod
    def load(cls, path: str | Path, *, system: LTISystem | None = None) -> GainTable:
        """Read and check a table file; with ``system``, also that it was made for it."""
        return table_io.load(cls, path, system=system)

    def check_system(self, system: LTISystem, *, source: str = "gain table") -> None:
        """Raise :class:`GainTableError` unless this table was designed for ``system``."""
        if system.fingerprint() != self.fingerprint:
            raise GainTableError(
                f"{source} was designed for another system ('{self.system_name}', fingerprint "
                f"{self.fingerprint[:12]}...) than '{system.name}' ({system.fingerprint()[:12]}...): design it again"
            )
        for i in range(1, system.N + 1):
            T = system.decomposition(i).T_o
            S = self.T_o(i)
            if T.shape != S.shape or not np.allclose(T, S, rtol=0, atol=1e-9):
                raise GainTableError(
                    f"{source}: stored observable basis of channel {i} differs from this "
                    "software's decomposition (made by another version?): design it again"
                )


def kalman_table(system: LTISystem, designs: Sequence[KalmanDesign]) -> GainTable:
    """A gain table of family ``"kalman"`` holding the offline Kalman ``designs`` of ``system``.

    The table's system fingerprint and observable bases are the system's (so loading checks
    them as for LMI tables); each design carries its noise model, rate and cycle sequence, and
    the checksum covers them (a table for another noise model or rate is another table).
    """
    designs = list(designs)
    if not designs:
        raise InvalidArgument("kalman_table needs at least one Kalman design")
    for d in designs:
        if not isinstance(d, KalmanDesign) or d.system.fingerprint() != system.fingerprint():
            raise InvalidArgument("kalman_table: every design must be a KalmanDesign of this system")
    return GainTable(
        system_name=system.name,
        fingerprint=system.fingerprint(),
        n=system.n,
        p=tuple(system.p),
        delta=(),
        settings={"family": "kalman", "rank_rtol": system.rtol},
        channels=[{"r": dc.r, "T_o": dc.T_o.tolist()} for dc in system.decompositions],
        family="kalman",
        kalman=[d.to_dict(arrays=True) for d in designs],
    )
