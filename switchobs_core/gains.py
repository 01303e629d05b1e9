"""Gain tables: the designs of :mod:`switchobs_core.design`, and their file.

A :class:`CycleDesign` holds, for one cycle (or for a residence-time box, the robust
design), one verified gain per channel with its eta, kappa, mu and the paper's cycle
factor f_ii = kappa_i exp(mu_i (tau - h_i) - eta_i h_i) (e:f11_le_delta_main).

A table holds one gain *family* (``family``): ``"lmi"``, the paper's LMI gains per cycle
(:mod:`switchobs_core.design`), or ``"kalman"``, offline periodic Kalman gains per sample phase
of a (super-)cycle at a nominal rate (:mod:`switchobs_core.kalman`). The observer, the exact
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

Paper labels (``e:...``, ``t:...``) resolve to numbers in ``docs/equations.md``.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import secrets
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, BinaryIO

import numpy as np

from ._version import __version__
from .certificate import cycle_factor
from .exceptions import GainTableError, InvalidArgument, SwitchobsError
from .families import TABLE_FAMILIES
from .files import check_output
from .kalman import KalmanDesign
from .loading import parse_json, read_text
from .schedule import CYCLE_ATOL, CYCLE_RTOL, Cycle
from .tablefile import decode, encode, is_binary, jsonable

if TYPE_CHECKING:
    from .system import LTISystem

__all__ = ["ChannelGain", "CycleDesign", "CertifyCheck", "GainTable", "FORMAT", "FORMAT_VERSION", "kalman_table"]

FORMAT = "switchobs-gain-table"
FORMAT_VERSION = 2
#: Versions this software reads (1: LMI tables from before the Kalman family).
READABLE_VERSIONS = (1, 2)


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
        """Check the paper's cycle condition for an observed cycle with these gains."""
        if not isinstance(observed, Cycle):
            raise InvalidArgument(f"observed must be a Cycle; got {observed!r}")
        if observed.N != self.N:
            raise InvalidArgument(f"observed cycle has {observed.N} channels; the design has {self.N}")
        fs, dom = [], True
        for i, c in enumerate(self.channels):
            act, ina = observed.active(i + 1), observed.inactive(i + 1)
            fs.append(c.factor(act, ina))
            ok_in = ina <= c.inactive * (1 + 1e-12) if c.mu >= 0 else ina >= c.inactive * (1 - 1e-12)
            dom &= act >= c.active * (1 - 1e-12) and ok_in
        ok = all(f <= d for f, d in zip(fs, self.delta))
        return CertifyCheck(ok=ok, dominated=bool(dom), f=tuple(fs), delta=self.delta)

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
                key = id(d)
                kd = self._kalman_cache.get(key)
                if kd is None:
                    try:
                        kd = self._kalman_cache[key] = KalmanDesign.from_dict(d, system)
                    except SwitchobsError as err:
                        raise GainTableError(f"gain table: stored Kalman design unusable: {err}") from None
                return kd
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

    # ------------------------------------------------------------------ file
    def _payload(self) -> dict[str, Any]:
        return {
            "format": FORMAT,
            "format_version": FORMAT_VERSION,
            "software_version": self.software_version,
            "system": {
                "name": self.system_name,
                "fingerprint": self.fingerprint,
                "n": self.n,
                "p": list(self.p),
                "N": self.N,
            },
            "delta": list(self.delta),
            "settings": self.settings,
            "channels": self.channels,
            "designs": [d.to_dict() for d in self.designs],
            "robust": None if self.robust is None else self.robust.to_dict(),
            "family": self.family,
            "kalman": self.kalman,
        }

    @staticmethod
    def _digest(payload: dict[str, Any]) -> str:
        text = json.dumps(payload, sort_keys=True, allow_nan=True, default=jsonable)
        return hashlib.sha256(text.encode()).hexdigest()

    def to_json(self) -> str:
        """The file's text."""
        payload = self._payload()
        _check_finite(payload, "gain table")
        payload["payload_sha256"] = self._digest(payload)
        return json.dumps(payload, indent=1, sort_keys=True, allow_nan=False, default=jsonable) + "\n"

    def _writer(self, *, binary: bool = False) -> Callable[[BinaryIO], Any]:
        """What writes the file to a binary handle: the JSON text, or (``binary``) the ``.npz``
        container of :mod:`.tablefile` (streamed: no copy of the file in memory)."""
        if not binary:
            text = self.to_json().encode()
            return lambda fh: fh.write(text)
        payload = self._payload()
        _check_finite(payload, "gain table")
        return lambda fh: encode(payload, fh)

    def save(self, path: str | Path) -> Path:
        """Write the table atomically (temporary file, fsync, rename): JSON, or the binary
        container of :mod:`.tablefile` when the name ends in ``.npz``.

        The file gets the mode a plain ``open(path, "w")`` would give (0666 less the umask,
        usually 0644), so a service running as another user can read it; ``tempfile`` would
        make it 0600."""
        path = check_output(path, "gain table", exc=GainTableError)   # never replace a directory or device
        write = self._writer(binary=path.suffix.lower() == ".npz")
        path.parent.mkdir(parents=True, exist_ok=True)
        while True:
            tmp = path.parent / f".{path.name}.{secrets.token_hex(6)}.tmp"
            try:
                fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)
                break
            except FileExistsError:  # pragma: no cover - 48 random bits
                continue
        try:
            with os.fdopen(fd, "wb") as fh:
                write(fh)
                fh.flush()
                os.fsync(fh.fileno())
            os.replace(tmp, path)
        except BaseException:
            tmp.unlink(missing_ok=True)
            raise
        return path

    @classmethod
    def from_json(cls, text: str, *, source: str = "<text>", system: LTISystem | None = None) -> GainTable:
        """Parse and check a table (see module docstring); ``system`` adds the fingerprint check."""

        try:
            data = parse_json(text, exc=GainTableError, source=source)
        except json.JSONDecodeError as err:
            raise GainTableError(
                f"{source}: not a complete gain table (JSON error at line {err.lineno}: {err.msg}); "
                "the file may be truncated: design it again"
            ) from None
        if not isinstance(data, dict) or data.get("format") != FORMAT:
            raise GainTableError(f"{source}: not a switchobs gain table (format field missing or wrong)")
        version = data.get("format_version")
        if isinstance(version, bool) or version not in READABLE_VERSIONS:
            raise GainTableError(
                f"{source}: gain table format version {version!r} "
                f"is not supported (this software reads versions {', '.join(map(str, READABLE_VERSIONS))})"
            )
        if "payload_sha256" not in data:
            raise GainTableError(f"{source}: the checksum (payload_sha256) is missing: the file was not written by "
                                 "switchobs or was edited; design it again")
        digest = data.pop("payload_sha256")
        _check_finite(data, source)
        if digest != cls._digest(data):
            raise GainTableError(
                f"{source}: checksum mismatch: the file was modified or corrupted after it was written"
            )
        return cls._from_payload(data, source=source, system=system)

    @classmethod
    def _from_payload(cls, data: dict[str, Any], *, source: str, system: LTISystem | None) -> GainTable:
        """The table of a checked payload (format, version and checksum already checked)."""
        _check_layout(data, source)
        try:
            sysd = data["system"]
            table = cls(
                system_name=str(sysd["name"]),
                fingerprint=str(sysd["fingerprint"]),
                n=int(sysd["n"]),
                p=tuple(int(x) for x in sysd["p"]),
                delta=tuple(float(x) for x in data["delta"]),
                settings=dict(data["settings"]),
                channels=list(data["channels"]),
                designs=[CycleDesign.from_dict(d) for d in data["designs"]],
                robust=None if data["robust"] is None else CycleDesign.from_dict(data["robust"]),
                software_version=str(data["software_version"]),
                family=str(data.get("family", "lmi")),
                kalman=list(data.get("kalman", [])),
            )
        except (KeyError, TypeError, ValueError) as err:
            raise GainTableError(f"{source}: malformed gain table ({type(err).__name__}: {err})") from None
        if table.family not in TABLE_FAMILIES:
            raise GainTableError(f"{source}: unknown gain family {table.family!r} (known: {', '.join(TABLE_FAMILIES)})")
        if table.family == "kalman" and not table.kalman:
            raise GainTableError(f"{source}: a kalman gain table without a Kalman design")
        if system is not None:
            table.check_system(system, source=source)
        return table

    @classmethod
    def load(cls, path: str | Path, *, system: LTISystem | None = None) -> GainTable:
        """Read and check a table file; with ``system``, also that it was made for it."""
        path = Path(path)
        if is_binary(path):
            return cls._from_payload(decode(path), source=str(path), system=system)
        try:
            text = read_text(path, exc=GainTableError, what="gain table")
        except FileNotFoundError:
            raise GainTableError(f"gain table {path} does not exist (make one with `switchobs design`)") from None
        return cls.from_json(text, source=str(path), system=system)

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


def _check_finite(obj: Any, source: str, where: str = "") -> None:
    """Raise GainTableError at the first non-finite float in a JSON-like tree (iterative walk)."""
    stack = [(obj, where)]
    while stack:
        node, at = stack.pop()
        if isinstance(node, np.ndarray):
            if not np.all(np.isfinite(node)):
                raise GainTableError(f"{source}: non-finite number in {at or 'top level'}")
        elif isinstance(node, float):
            if not math.isfinite(node):
                raise GainTableError(f"{source}: non-finite number {node} at {at or 'top level'}")
        elif isinstance(node, dict):
            stack.extend((v, f"{at}.{k}" if at else str(k)) for k, v in reversed(list(node.items())))
        elif isinstance(node, (list, tuple)):
            stack.extend((v, f"{at}[{i}]") for i, v in reversed(list(enumerate(node))))


class _Layout:
    """Checks of a parsed table's layout (types and sizes of what the tools read), so a table
    with a valid checksum but written by something else is refused in one line, naming the key."""

    def __init__(self, source: str) -> None:
        self.source = source

    def fail(self, where: str, what: str) -> GainTableError:
        return GainTableError(f"{self.source}: malformed gain table: {where} must be {what}")

    def get(self, d: dict, key: str, where: str) -> Any:
        if key not in d:
            raise GainTableError(f"{self.source}: malformed gain table: {where}{'.' if where else ''}{key} is missing")
        return d[key]

    def mapping(self, x: Any, where: str) -> dict:
        if not isinstance(x, dict):
            raise self.fail(where, "an object")
        return x

    def number(self, x: Any, where: str, *, none: bool = False) -> None:
        if x is None and none:
            return
        if isinstance(x, bool) or not isinstance(x, (int, float)):
            raise self.fail(where, "a number")

    def integer(self, x: Any, where: str, lo: int = 0, hi: int | None = None) -> int:
        if isinstance(x, bool) or not isinstance(x, int) or x < lo or (hi is not None and x > hi):
            raise self.fail(where, f"a whole number in {lo}..{hi if hi is not None else ''}")
        return x

    def string(self, x: Any, where: str) -> None:
        if not isinstance(x, str):
            raise self.fail(where, "a string")

    def numbers(self, x: Any, where: str, size: int | None = None) -> list:
        if not isinstance(x, list) or (size is not None and len(x) != size):
            raise self.fail(where, "a list of numbers" + (f" of length {size}" if size is not None else ""))
        for i, v in enumerate(x):
            self.number(v, f"{where}[{i}]")
        return x

    def matrix(self, x: Any, where: str, rows: int, cols: int) -> None:
        if not isinstance(x, list) or len(x) != rows:
            raise self.fail(where, f"a {rows} x {cols} matrix (a list of {rows} rows)")
        for i, row in enumerate(x):
            self.numbers(row, f"{where}[{i}]", cols)


def _check_layout(data: dict[str, Any], source: str) -> None:
    """Raise GainTableError naming the key if the table's layout is not the one this software
    writes (module docstring); what the loader and ``switchobs show`` read is checked."""
    c = _Layout(source)
    sysd = c.mapping(c.get(data, "system", ""), "system")
    c.string(c.get(sysd, "name", "system"), "system.name")
    c.string(c.get(sysd, "fingerprint", "system"), "system.fingerprint")
    n = c.integer(c.get(sysd, "n", "system"), "system.n", 1)
    p = c.get(sysd, "p", "system")
    if not isinstance(p, list) or len(p) < 2:
        raise c.fail("system.p", "a list of N >= 2 output sizes")
    for i, v in enumerate(p):
        c.integer(v, f"system.p[{i}]", 1)
    N = len(p)
    c.string(c.get(data, "software_version", ""), "software_version")
    family = data.get("family", "lmi")
    c.string(family, "family")
    settings = c.mapping(c.get(data, "settings", ""), "settings")
    c.numbers(c.get(data, "delta", ""), "delta", N if family == "lmi" else None)
    chans = c.get(data, "channels", "")
    if not isinstance(chans, list) or len(chans) != N:
        raise c.fail("channels", f"a list of N = {N} channel entries")
    rs = []
    for i, ch in enumerate(chans):
        w = f"channels[{i}]"
        c.mapping(ch, w)
        r = c.integer(c.get(ch, "r", w), f"{w}.r", 1, n)
        rs.append(r)
        c.matrix(c.get(ch, "T_o", w), f"{w}.T_o", n, r)
        if family == "lmi":
            c.number(c.get(ch, "mu", w), f"{w}.mu")
            kc = c.mapping(c.get(ch, "kappa_curve", w), f"{w}.kappa_curve")
            eta = c.numbers(c.get(kc, "eta", f"{w}.kappa_curve"), f"{w}.kappa_curve.eta")
            c.numbers(c.get(kc, "kappa", f"{w}.kappa_curve"), f"{w}.kappa_curve.kappa", len(eta))
    if family == "lmi":
        for key in ("margin", "solver"):
            c.get(settings, key, "settings")
    designs = c.get(data, "designs", "")
    if not isinstance(designs, list):
        raise c.fail("designs", "a list")
    robust = c.get(data, "robust", "")
    for w, d in [(f"designs[{k}]", d) for k, d in enumerate(designs)] + ([("robust", robust)] if robust else []):
        _check_design(c, d, w, n, p, rs)
    kalman = data.get("kalman", [])
    if not isinstance(kalman, list):
        raise c.fail("kalman", "a list")
    for k, d in enumerate(kalman):
        w = f"kalman[{k}]"
        c.mapping(d, w)
        cycles = c.get(d, "cycles", w)
        if not isinstance(cycles, list):
            raise c.fail(f"{w}.cycles", "a list of cycles")
        for j, h in enumerate(cycles):
            c.numbers(h, f"{w}.cycles[{j}]", N)
        if "dead_time" in d:
            c.number(d["dead_time"], f"{w}.dead_time")
        for key in ("rate", "rho", "norm"):
            c.number(c.get(d, key, w), f"{w}.{key}")
        c.integer(c.get(d, "periods", w), f"{w}.periods")
        c.mapping(c.get(d, "noise", w), f"{w}.noise")
        for key in ("periodic", "startup"):
            ph = c.mapping(c.get(d, key, w), f"{w}.{key}")
            if not isinstance(c.get(ph, "channel", f"{w}.{key}"), list):
                raise c.fail(f"{w}.{key}.channel", "a list")


def _check_design(c: _Layout, d: Any, w: str, n: int, p: list[int], rs: list[int]) -> None:
    c.mapping(d, w)
    c.string(c.get(d, "kind", w), f"{w}.kind")
    cyc = c.get(d, "cycle", w)
    if cyc is not None:
        c.numbers(c.get(c.mapping(cyc, f"{w}.cycle"), "h", f"{w}.cycle"), f"{w}.cycle.h", len(p))
        if "dead_time" in cyc:
            c.number(cyc["dead_time"], f"{w}.cycle.dead_time")
    hb = c.get(d, "h_bounds", w)
    if hb is not None:
        c.numbers(hb, f"{w}.h_bounds", 2)
    c.numbers(c.get(d, "delta", w), f"{w}.delta", len(p))
    chans = c.get(d, "channels", w)
    if not isinstance(chans, list) or len(chans) != len(p):
        raise c.fail(f"{w}.channels", f"a list of N = {len(p)} gains")
    for i, g in enumerate(chans):
        wi = f"{w}.channels[{i}]"
        c.mapping(g, wi)
        c.number(c.get(g, "eta_min", wi), f"{wi}.eta_min", none=True)
        for key in ("eta", "kappa", "kappa_star", "mu", "active", "inactive", "f", "eta_verified", "abscissa"):
            c.number(c.get(g, key, wi), f"{wi}.{key}")
        c.matrix(c.get(g, "L_o", wi), f"{wi}.L_o", rs[i], p[i])
        c.matrix(c.get(g, "L", wi), f"{wi}.L", n, p[i])
        c.matrix(c.get(g, "P", wi), f"{wi}.P", rs[i], rs[i])
