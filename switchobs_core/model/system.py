"""The LTI system with N scheduled output channels (e:system, e:outputs) and assumption A1.

``x' = A x + B u``, ``y = C_rho x`` with rho(t) in {1, ..., N}; only one channel is
available at a time. The paper has N = 2; everything here is written for N >= 2.

YAML schema (``LTISystem.from_yaml``)::

    name: my_system                # optional
    states: [x1, x2, x3]           # optional state labels (default x0, x1, ...)
    A: [[0, 1, 0], [0, 0, 1], [-1, -2, -3]]
    B: [[0], [0], [1]]             # optional (default: no input, m = 0)
    channels:                      # N >= 2 entries, visited in this cyclic order
      - name: front                # optional
        C: [[1, 0, 0]]
        outputs: [range]           # optional output labels
      - C: [[0, 1, 0]]

or a built-in scenario with its parameters::

    scenario: camera_agents        # see switchobs_core.model.scenarios
    agents: 3
    D_agents: [[0, 0.2], [0, 0.1], [0, 0.15]]

Paper labels (``e:...``, ``t:...``) resolve to numbers in ``docs/equations.md``.
"""

from __future__ import annotations

import hashlib
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from ..exceptions import InvalidSystem, UnobservableSystem
from ..loading import load_yaml, number_matrix
from ..numerics.scaling import balance, balanced
from ..validation import MAX_ABS_SYSTEM_ENTRY, as_matrix
from .decomposition import DEFAULT_RTOL, Decomposition, _check_rtol, _decompose, unobservable_subspace

__all__ = ["LTISystem", "ChannelInfo", "read_spec"]


@dataclass(frozen=True)
class ChannelInfo:
    """What one channel (A, C_i) sees on its own."""

    index: int
    name: str
    p: int
    r: int
    observable: bool
    detectable: bool
    mu: float
    unobservable_eigenvalues: tuple[complex, ...]


@dataclass(frozen=True, eq=False)
class LTISystem:
    """An LTI system with N >= 2 output channels, only one available at a time.

    ``sys = LTISystem(A, B, [C_1, ..., C_N])``

    Parameters
    ----------
    A : (n, n) array_like
    B : (n, m) array_like or None
        ``None`` means no input (m = 0).
    C : sequence of (p_i, n) array_like
        The channel output matrices, in the cyclic order the schedule visits them.
    name : str
    state_labels, channel_names, output_labels : optional labels.
    rtol : float
        Rank tolerance of the observability decompositions (``decomposition.DEFAULT_RTOL``).

    Raises
    ------
    InvalidSystem
        Wrong shapes, non-finite entries, fewer than two channels, a channel that sees
        nothing (r_i = 0).
    UnobservableSystem
        Assumption A1 fails: (A, [C_1; ...; C_N]) is not observable. The message names
        the unobservable directions and modes.
    """

    A: np.ndarray
    B: np.ndarray
    C: tuple[np.ndarray, ...]
    name: str = "system"
    state_labels: tuple[str, ...] = ()
    channel_names: tuple[str, ...] = ()
    output_labels: tuple[tuple[str, ...], ...] = ()
    rtol: float = DEFAULT_RTOL
    _decomp: tuple[Decomposition, ...] = field(default=(), repr=False)

    def __init__(
        self,
        A: ArrayLike,
        B: ArrayLike | None,
        C: Sequence[ArrayLike],
        *,
        name: str = "system",
        state_labels: Sequence[str] | None = None,
        channel_names: Sequence[str] | None = None,
        output_labels: Sequence[Sequence[str]] | None = None,
        rtol: float = DEFAULT_RTOL,
    ) -> None:
        A = as_matrix(A, "A", square=True, exc=InvalidSystem, max_abs=MAX_ABS_SYSTEM_ENTRY)
        n = A.shape[0]
        if n == 0:
            raise InvalidSystem("A must have at least one state")
        if B is None:
            B = np.zeros((n, 0))
        else:
            B = as_matrix(B, "B", rows=n, exc=InvalidSystem, max_abs=MAX_ABS_SYSTEM_ENTRY)
        if isinstance(C, np.ndarray) and C.ndim == 2:
            raise InvalidSystem("C must be a list of channel output matrices [C_1, ..., C_N]")
        C = tuple(as_matrix(Ci, f"C_{i + 1}", cols=n, exc=InvalidSystem, max_abs=MAX_ABS_SYSTEM_ENTRY)
                  for i, Ci in enumerate(C))
        if len(C) < 2:
            raise InvalidSystem(f"C: a switched-output system needs N >= 2 channels (C_1..C_N); got {len(C)}")
        for i, Ci in enumerate(C):
            if Ci.shape[0] == 0:
                raise InvalidSystem(f"C_{i + 1} has no rows: channel {i + 1} measures nothing")
        N = len(C)
        labels = tuple(state_labels) if state_labels is not None else tuple(f"x{k}" for k in range(n))
        if len(labels) != n:
            raise InvalidSystem(f"state_labels has {len(labels)} entries; expected n = {n}")
        cnames = tuple(channel_names) if channel_names is not None else tuple(f"channel{i + 1}" for i in range(N))
        if len(cnames) != N:
            raise InvalidSystem(f"channel_names has {len(cnames)} entries; expected N = {N}")
        dup = sorted({c for c in cnames if cnames.count(c) > 1})
        if dup:
            raise InvalidSystem(f"channel names must be distinct; {', '.join(map(repr, dup))} names more than one "
                                "channel")
        if output_labels is None:
            olabels = tuple(tuple(f"y{i + 1}[{k}]" for k in range(Ci.shape[0])) for i, Ci in enumerate(C))
        else:
            olabels = tuple(tuple(o) for o in output_labels)
            if len(olabels) != N or any(len(o) != Ci.shape[0] for o, Ci in zip(olabels, C)):
                raise InvalidSystem("output_labels must give one label per row of each C_i")
        for arr in (A, B, *C):
            arr.setflags(write=False)
        object.__setattr__(self, "A", A)
        object.__setattr__(self, "B", B)
        object.__setattr__(self, "C", C)
        object.__setattr__(self, "name", str(name))
        object.__setattr__(self, "state_labels", labels)
        object.__setattr__(self, "channel_names", cnames)
        object.__setattr__(self, "output_labels", olabels)
        object.__setattr__(self, "rtol", float(rtol))
        # one SVD of A and one pattern of its nonzeros for every channel (A and C checked above)
        norm_a, nz, rtol_ = float(np.linalg.norm(A, 2)), A != 0, _check_rtol(rtol)
        decomp = tuple(_decompose(A, Ci, rtol_, norm_a, nz) for Ci in C)
        for i, d in enumerate(decomp):
            if d.r == 0:
                raise InvalidSystem(f"channel {i + 1} ({cnames[i]}) observes no direction of the state (r_{i + 1} = 0)")
        object.__setattr__(self, "_decomp", decomp)
        self._check_a1()

    # ------------------------------------------------------------------ sizes
    @property
    def n(self) -> int:
        """Number of states."""
        return self.A.shape[0]

    @property
    def m(self) -> int:
        """Number of inputs (0 when there is none)."""
        return self.B.shape[1]

    @property
    def N(self) -> int:
        """Number of output channels."""
        return len(self.C)

    @property
    def p(self) -> tuple[int, ...]:
        """Output dimension p_i of each channel."""
        return tuple(Ci.shape[0] for Ci in self.C)

    @property
    def C_stacked(self) -> np.ndarray:
        """The aggregated output matrix C = [C_1; ...; C_N] (e:C_agg)."""
        return np.vstack(self.C)

    # --------------------------------------------------------- decompositions
    def decomposition(self, channel: int) -> Decomposition:
        """Orthogonal observability decomposition of (A, C_channel), channel 1-based."""
        self._check_channel(channel)
        return self._decomp[channel - 1]

    @property
    def decompositions(self) -> tuple[Decomposition, ...]:
        """Decompositions of all channels, in channel order."""
        return self._decomp

    def channels(self) -> list[ChannelInfo]:
        """Per channel: observable dimension r_i, observable/detectable, mu_i."""
        out = []
        for i, d in enumerate(self._decomp):
            out.append(
                ChannelInfo(
                    index=i + 1,
                    name=self.channel_names[i],
                    p=self.p[i],
                    r=d.r,
                    observable=d.observable,
                    detectable=d.detectable,
                    mu=d.mu,
                    unobservable_eigenvalues=tuple(complex(z) for z in d.unobservable_eigenvalues),
                )
            )
        return out

    @property
    def H(self) -> np.ndarray:
        """H = [T_1o'; ...; T_No'] of Theorem ``t:xtilde_bound``."""
        return np.vstack([d.T_o.T for d in self._decomp])

    @property
    def alpha(self) -> float:
        """alpha = 1 / sigma_min(H) (e:alpha_def)."""
        return float(1.0 / np.linalg.svd(self.H, compute_uv=False)[-1])

    def _check_channel(self, channel: int) -> None:
        if not isinstance(channel, (int, np.integer)) or not 1 <= channel <= self.N:
            raise InvalidSystem(f"channel must be an integer in 1..{self.N}; got {channel!r}")

    def _check_a1(self) -> None:
        """A1 decided in balanced coordinates, so that the units of the state do not decide it.

        ``A_b = D^{-1} A D`` (:func:`~switchobs_core.numerics.scaling.balance`, powers of two: exact)
        and ``C_b = C D`` with every row scaled to unit norm (the kernel of ``C`` does not depend on
        the rows' units); the unobservable subspace ``V_b`` of ``(A_b, C_b)`` is ``A_b``-invariant,
        so the modes named are the eigenvalues of ``V_b' A_b V_b`` (eigenvalues of ``A``), and the
        directions named are the columns of ``D V_b`` in the user's units, each of unit norm. A
        rank tolerance relative to ``||A||_2`` instead hides the slow modes of a system whose
        entries span 1e-6..1e6 and names directions that are not invariant."""
        d = balance(self.A)
        Ab = balanced(self.A, d)
        Cb = self.C_stacked * d[None, :]
        rn = np.linalg.norm(Cb, axis=1)
        Cb = Cb[rn > 0] / rn[rn > 0, None]
        Vb = unobservable_subspace(Ab, Cb, rtol=self.rtol)
        if Vb.shape[1] == 0:
            return
        dirs = []
        for k in range(Vb.shape[1]):
            v = d * Vb[:, k]
            v = v / np.linalg.norm(v)
            v = v if v[np.argmax(np.abs(v))] > 0 else -v
            terms = [f"{v[j]:+.3g}*{self.state_labels[j]}" for j in np.argsort(-np.abs(v))[:4] if abs(v[j]) > 1e-6]
            dirs.append(" ".join(terms))
        modes = ", ".join(f"{z:.4g}" for z in np.sort_complex(np.linalg.eigvals(Vb.T @ Ab @ Vb)))
        raise UnobservableSystem(
            f"assumption A1 fails for {self.name}: (A, [C_1; ...; C_{self.N}]) has observable "
            f"dimension {self.n - Vb.shape[1]} < n = {self.n}. Unobservable direction(s): {'; '.join(dirs)}. "
            f"Unobservable mode(s): {modes}. Add a channel that measures them."
        )

    # ----------------------------------------------------------- identity
    def fingerprint(self) -> str:
        """SHA-256 (hex) of the shapes and float64 bytes of A, B, C_1..C_N."""
        h = hashlib.sha256()
        for M in (self.A, self.B, *self.C):
            h.update(np.asarray(M.shape, dtype="<i8").tobytes())
            h.update(np.ascontiguousarray(M, dtype="<f8").tobytes())
        return h.hexdigest()

    def describe(self) -> str:
        """A few lines: sizes, and what each channel sees."""
        lines = [f"{self.name}: n = {self.n}, m = {self.m}, N = {self.N} channels, stacked pair observable (A1)"]
        for c in self.channels():
            kind = "observable" if c.observable else ("detectable" if c.detectable else "NOT detectable")
            lines.append(f"  channel {c.index} ({c.name}): p = {c.p}, r = {c.r}, {kind}, mu = {c.mu:.4f}")
        return "\n".join(lines)

    # ------------------------------------------------------------- loading
    @classmethod
    def from_dict(cls, spec: dict[str, Any], *, source: str = "<dict>") -> LTISystem:
        """Build a system from a parsed YAML mapping (schema in the module docstring)."""
        if not isinstance(spec, dict):
            raise InvalidSystem(f"{source}: the top level must be a mapping with A and channels")
        if "scenario" in spec:
            raise InvalidSystem(f"{source}: a 'scenario' mapping names a built-in scenario; build it with "
                                "switchobs_core.model.scenarios.system_from_dict or load_system")
        for key in ("A", "channels"):
            if key not in spec:
                raise InvalidSystem(f"{source}: missing required key '{key}'")
        unknown = set(spec) - {"name", "states", "A", "B", "channels"}
        if unknown:
            raise InvalidSystem(f"{source}: unknown key(s) {sorted(map(str, unknown))}")
        try:
            return cls._from_checked_dict(spec, source)
        except InvalidSystem as err:
            raise type(err)(f"{source}: {err}") from None

    @classmethod
    def _from_checked_dict(cls, spec: dict[str, Any], source: str) -> LTISystem:
        """:meth:`from_dict` after its key checks; messages without the ``source`` prefix."""
        chans = spec["channels"]
        if not isinstance(chans, list):
            raise InvalidSystem("'channels' must be a list of mappings with a 'C' entry")
        A = number_matrix(spec["A"], "A", exc=InvalidSystem)
        B = None if spec.get("B") is None else number_matrix(spec["B"], "B", exc=InvalidSystem)
        Cs, names, outs = [], [], []
        for i, ch in enumerate(chans):
            if not isinstance(ch, dict) or "C" not in ch:
                raise InvalidSystem(f"channels[{i}] must be a mapping with a 'C' entry")
            extra = set(ch) - {"name", "C", "outputs"}
            if extra:
                raise InvalidSystem(f"channels[{i}]: unknown key(s) {sorted(map(str, extra))} "
                                    "(known: name, C, outputs)")
            Cs.append(number_matrix(ch["C"], f"channels[{i}].C", exc=InvalidSystem))
            names.append(_label(ch.get("name", f"channel{i + 1}"), f"channels[{i}].name"))
            o = ch.get("outputs")
            if o is not None and not isinstance(o, list):
                raise InvalidSystem(f"channels[{i}].outputs must be a list of labels")
            outs.append(None if o is None else [_label(x, f"channels[{i}].outputs") for x in o])
        states = spec.get("states")
        if "states" in spec and not isinstance(states, list):
            raise InvalidSystem("'states' must be a list of labels")
        return cls(
            A,
            B,
            Cs,
            name=_label(spec.get("name", Path(source).stem), "name"),
            state_labels=[_label(x, "states") for x in states] if states is not None else None,
            channel_names=names,
            output_labels=outs if all(o is not None for o in outs) else None,
        )

    @classmethod
    def from_yaml(cls, path: str | Path) -> LTISystem:
        """Load a system from a YAML file (schema in the module docstring; a ``scenario``
        file is read by :func:`switchobs_core.model.scenarios.load_system`)."""
        return cls.from_dict(read_spec(path), source=str(path))

    def to_dict(self) -> dict[str, Any]:
        """The YAML mapping that :meth:`from_dict` reads back to this system."""
        return {
            "name": self.name,
            "states": list(self.state_labels),
            "A": self.A.tolist(),
            "B": self.B.tolist(),
            "channels": [
                {"name": nm, "C": Ci.tolist(), "outputs": list(o)}
                for nm, Ci, o in zip(self.channel_names, self.C, self.output_labels)
            ],
        }


def _label(x: Any, where: str) -> str:
    """A name or label read from a file: a plain value (string, number), not a list or mapping."""
    if isinstance(x, (dict, list)) or x is None:
        kind = "a mapping" if isinstance(x, dict) else "a list" if isinstance(x, list) else "null"
        raise InvalidSystem(f"{where} must be a name (a string); got {kind}")
    return str(x)


def read_spec(path: str | Path) -> Any:
    """The parsed YAML mapping of a system file (schema in the module docstring), read with
    the bounds of :mod:`switchobs_core.loading` (size, UTF-8, no aliases, no duplicate keys,
    nesting depth)."""
    try:
        return load_yaml(path, exc=InvalidSystem, what="system file")
    except FileNotFoundError:
        raise InvalidSystem(f"system file {path} does not exist") from None
