"""The registry of gain families: one entry per family, read by the observer, the file schema,
the command line and the ROS configuration (beyond the paper).

A *gain family* is one type behind the protocol of :mod:`switchobs_core.runtime.families.base`: it picks
the gain of every sample, applies it, and says which error map it applied and which covariance
it keeps. :class:`~switchobs_core.runtime.observer.SwitchedObserver` orchestrates propagation, the
family and the rigorous bound (:mod:`switchobs_core.bounds.rigorous`) and never names a family.

======================  =========================================  ======================
name                    type (module)                              gain table it reads
======================  =========================================  ======================
``lmi``                 ``LmiGains`` (:mod:`switchobs_core.runtime.families.lmi`)          ``lmi`` (the paper)
``kalman``              ``KalmanTableGains`` (:mod:`switchobs_core.runtime.families.kalman`)  ``kalman``
``kalman-online``       ``OnlineKalmanGains`` (:mod:`switchobs_core.runtime.families.online`) any (designs ``lmi``)
======================  =========================================  ======================

The types are imported on first use (:meth:`FamilyEntry.type`), so this module is a leaf that
the table file's schema (:mod:`switchobs_core.table.gains`) can read without an import circle. Adding a family:
docs/architecture.md, "Adding a gain family".
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass
from typing import Any

from .exceptions import InvalidArgument

__all__ = ["FamilyEntry", "REGISTRY", "FAMILY_NAMES", "TABLE_FAMILIES", "DESIGNABLE", "family_entry",
           "family_of_table", "design_family_table"]


@dataclass(frozen=True)
class FamilyEntry:
    """One gain family.

    Attributes
    ----------
    name : str
        What users write (parameter ``gain_family``, ``--gains``, ``family=``).
    module, type_name : str
        Where its type lives: ``switchobs_core.<module>.<type_name>``.
    table : str
        The family of the gain table it is designed into and reads (``stored`` families: their own
        name); a family that needs no stored gains names the table it designs when none is given.
    stored : bool
        Whether a gain table file can hold this family (the schema of :mod:`switchobs_core.table.gains`).
    summary : str
        One line for help texts.
    rate : bool
        Whether its design needs the nominal sample rate (and a noise model, which the stored
        table then brings: a Kalman table is designed for one).
    robust : str
        The family that serves robust mode (no promised schedule): its own name, or the one it
        hands over to (a Kalman table needs its schedule: the recursion runs online instead).
    """

    name: str
    module: str
    type_name: str
    table: str
    stored: bool
    summary: str
    rate: bool = False
    robust: str = ""

    def __post_init__(self) -> None:
        if not self.robust:
            object.__setattr__(self, "robust", self.name)

    def type(self) -> Any:
        """The family's type (imported on first use)."""
        return getattr(importlib.import_module(f"{__package__}.{self.module}"), self.type_name)


#: Every gain family, by name.
REGISTRY: dict[str, FamilyEntry] = {e.name: e for e in (
    FamilyEntry("lmi", "runtime.families.lmi", "LmiGains", "lmi", True,
                "the paper's LMI gains, per cycle"),
    FamilyEntry("kalman", "runtime.families.kalman", "KalmanTableGains", "kalman", True,
                "offline periodic Kalman gains per sample phase (a cache of the Riccati recursion)", rate=True,
                robust="kalman-online"),
    FamilyEntry("kalman-online", "runtime.families.online", "OnlineKalmanGains", "lmi", False,
                "the Riccati recursion online (any schedule)"),
)}
#: Names of all families.
FAMILY_NAMES: tuple[str, ...] = tuple(REGISTRY)
#: Families a gain table file can hold.
TABLE_FAMILIES: tuple[str, ...] = tuple(e.name for e in REGISTRY.values() if e.stored)
#: Families a design produces a table for (the CLI's ``--gains``).
DESIGNABLE: tuple[str, ...] = TABLE_FAMILIES


def family_entry(name: Any) -> FamilyEntry:
    """The registry entry of ``name``; :class:`InvalidArgument` with the known names otherwise."""
    entry = REGISTRY.get(name) if isinstance(name, str) else None
    if entry is None:
        raise InvalidArgument(f"family must be one of {FAMILY_NAMES}; got {name!r}")
    return entry


def family_of_table(table: Any) -> str:
    """The family a gain table holds (tables from before families hold LMI gains)."""
    return getattr(table, "family", "lmi")


def design_family_table(name: str, system: Any, cycles: Any, *, robust: Any = None, delta: float = 0.99,
                 rate: float = 0.0, noise: Any = None) -> Any:
    """A gain table for family ``name`` (what its entry's ``table`` family designs)."""
    return family_entry(family_entry(name).table).type().design_table(
        system, cycles, robust=robust, delta=delta, rate=rate, noise=noise)
