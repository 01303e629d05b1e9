"""The noise model of the Kalman gain families: measurement noise, process noise, P0.

Beyond the paper: the paper's plant (e:system) and outputs (e:outputs) are noise-free. The
Kalman families model

.. math::

    \\dot x = A x + B u + w, \\quad E[w(t) w(s)'] = Q_c \\delta(t - s), \\qquad
    y_k = C_{\\rho(t_k)} x(t_k) + v_k, \\quad v_k \\sim N(0, R_{\\rho}),

with ``R_rho = diag(std_1^2, ..., std_p^2)`` over the rows of channel ``rho`` and an initial
covariance ``P0`` of the estimation error.

YAML (the ``noise:`` mapping of a system file)::

    noise:
      measurement_std: 0.001          # one scalar for every row of every channel,
      # measurement_std: [0.001, 0.002]            # or one per channel (N entries),
      # measurement_std: [[1e-3, 1e-3, 2e-3, 2e-3], 0.001]   # or per row (p_i entries)
      process_std: 0.01               # Qc = q^2 I (the simulator's --process-noise q)
      # process_intensity: 1e-4       # or Qc itself: scalar (q I), n-vector (diag) or n x n PSD
      P0: 100.0                       # scalar (p I), n-vector (diag) or n x n PSD matrix

Every key is optional; missing ones take the values of :func:`default_noise`. ``process_std``
and ``process_intensity`` are exclusive. Numbers written as strings (PyYAML reads ``1e-3``
without a dot as a string) are accepted; booleans are not.

Command-line overrides (``--meas-noise STD`` / ``--process-noise Q``) arrive as
``meas_std=STD`` (any form of ``measurement_std``) and ``process_q=Q``, meaning
``Qc = Q^2 I``: the same convention as the simulator's and the bag generator's
``--process-noise`` (``switchobs_core.sim.plant.Plant``), so the same number on both sides
declares the noise that the data were made with.
"""

from __future__ import annotations

import hashlib
import json
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..exceptions import NoiseModelError
from ..loading import as_number

__all__ = [
    "NoiseModel",
    "default_noise",
    "DEFAULT_MEAS_STD",
    "DEFAULT_PROCESS_STD",
    "DEFAULT_P0",
    "NOISE_KEYS",
    "MAX_ABS_ENTRY",
]

#: Default measurement noise std of every output row (1 mm for the camera scenarios).
DEFAULT_MEAS_STD = 1e-3
#: Default process noise: ``Qc = DEFAULT_PROCESS_STD**2 I`` (1e-4 per state and second).
DEFAULT_PROCESS_STD = 1e-2
#: Default initial covariance ``P0 = DEFAULT_P0 I`` (std 10 in every state unit: a vague prior).
DEFAULT_P0 = 100.0
#: Keys of the ``noise:`` mapping.
NOISE_KEYS = ("measurement_std", "process_std", "process_intensity", "P0")

# Relative tolerance of the symmetry and PSD checks of Qc and P0 (times max(1, ||M||_2)).
_SYM_RTOL = 1e-10
_PSD_RTOL = 1e-12


#: Largest magnitude of a covariance or intensity entry (a std: its square root).
MAX_ABS_ENTRY = 1e100


def _number(x: Any, where: str) -> float:
    """``x`` as a float; strings holding a number are accepted, booleans are not
    (:func:`switchobs_core.loading.as_number`; finiteness is the caller's check)."""
    return as_number(x, where, exc=NoiseModelError, finite=False)


def _array(x: Any, where: str) -> np.ndarray:
    """A nested list / array of numbers as a float array (booleans and strings refused)."""
    if isinstance(x, np.ndarray):
        if x.dtype == bool:
            raise NoiseModelError(f"{where} must hold numbers; got a boolean array")
        if not np.issubdtype(x.dtype, np.number):
            return _array(x.tolist(), where)
        return x.astype(float)
    if isinstance(x, (list, tuple)):
        if _plain_numbers(x):       # the common case (a table's P0 at n = 132: 17 424 entries) at C speed
            try:
                return np.array(x, dtype=float)
            except ValueError:
                pass                # ragged: the element-wise path below says so
        rows = [_array(v, where) for v in x]
        try:
            return np.array(rows, dtype=float)
        except ValueError:
            raise NoiseModelError(
                f"{where} is a ragged nested list; give a scalar, a vector or a square matrix"
            ) from None
    return np.array(_number(x, where))


def _plain_numbers(x: list | tuple) -> bool:
    """``x`` is a list of ints and floats or a list of such lists (no booleans, strings or deeper
    nesting): :func:`_array` may convert it at once."""
    plain = {int, float}
    if set(map(type, x)) <= plain:
        return True
    return all(type(r) in (list, tuple) and set(map(type, r)) <= plain for r in x)


def _std(x: Any, where: str) -> float:
    val = _number(x, where)
    if not math.isfinite(val) or val <= 0:
        raise NoiseModelError(f"{where} must be a finite standard deviation > 0; got {val}")
    if val > math.sqrt(MAX_ABS_ENTRY):
        raise NoiseModelError(f"{where} = {val:.3g} is beyond the supported {math.sqrt(MAX_ABS_ENTRY):g}")
    return val


def _psd(x: Any, n: int, where: str, *, square_scalar: bool = False) -> np.ndarray:
    """Scalar (times I), n-vector (diagonal) or n x n symmetric PSD matrix; checked, symmetrised.

    Entries beyond :data:`MAX_ABS_ENTRY` in magnitude are refused (squares and sums of them
    would overflow, and no physical covariance is that large)."""
    arr = _array(x, where)
    with np.errstate(invalid="ignore"):
        big = np.isfinite(arr) & (np.abs(arr) > (math.sqrt(MAX_ABS_ENTRY) if square_scalar and arr.ndim == 0
                                                 else MAX_ABS_ENTRY))
    if np.any(big):
        raise NoiseModelError(f"{where}: an entry of magnitude {float(np.max(np.abs(arr[big]))):.3g} is beyond the "
                              f"supported {MAX_ABS_ENTRY:g}")
    if arr.ndim == 0:
        v = float(arr)
        if not math.isfinite(v) or v < 0:
            raise NoiseModelError(f"{where} must be a finite number >= 0; got {v}")
        return (v * v if square_scalar else v) * np.eye(n)
    if arr.ndim == 1:
        if arr.size != n:
            raise NoiseModelError(f"{where} as a vector needs n = {n} entries (the diagonal); got {arr.size}")
        if not np.all(np.isfinite(arr)) or np.any(arr < 0):
            raise NoiseModelError(f"{where} diagonal must be finite and >= 0; got {arr.tolist()}")
        return np.diag(arr)
    if arr.ndim != 2 or arr.shape != (n, n):
        raise NoiseModelError(f"{where} must be a scalar, an {n}-vector or an ({n}, {n}) matrix; got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        i, j = np.argwhere(~np.isfinite(arr))[0]
        raise NoiseModelError(f"{where} has a non-finite entry ({arr[i, j]}) at row {i}, column {j}")
    scale = max(1.0, float(np.linalg.norm(arr, 2)))
    asym = float(np.max(np.abs(arr - arr.T))) if n else 0.0
    if asym > _SYM_RTOL * scale:
        raise NoiseModelError(f"{where} must be symmetric; max |M - M'| = {asym:.3g}")
    arr = 0.5 * (arr + arr.T)
    lam = float(np.linalg.eigvalsh(arr)[0]) if n else 0.0
    if lam < -_PSD_RTOL * scale:
        raise NoiseModelError(f"{where} must be positive semidefinite; its smallest eigenvalue is {lam:.3g}")
    return arr


def _meas_std(x: Any, p: Sequence[int], where: str) -> tuple[tuple[float, ...], ...]:
    """Expand a scalar / per-channel / per-row std into one tuple per channel."""
    N = len(p)
    if isinstance(x, np.ndarray):
        x = x.tolist()
    if not isinstance(x, (list, tuple)):
        s = _std(x, where)
        return tuple((s,) * pi for pi in p)
    if len(x) != N:
        raise NoiseModelError(f"{where} as a list needs one entry per channel (N = {N}); got {len(x)}")
    out = []
    for i, (xi, pi) in enumerate(zip(x, p)):
        wi = f"{where}[channel {i + 1}]"
        if isinstance(xi, np.ndarray):
            xi = xi.tolist()
        if isinstance(xi, (list, tuple)):
            if len(xi) != pi:
                raise NoiseModelError(f"{wi} needs p_{i + 1} = {pi} entries (one per output row); got {len(xi)}")
            out.append(tuple(_std(v, f"{wi}[row {r}]") for r, v in enumerate(xi)))
        else:
            out.append((_std(xi, wi),) * pi)
    return tuple(out)


@dataclass(frozen=True, eq=False)
class NoiseModel:
    """Measurement std per output row and channel, process intensity ``Q_c``, initial ``P0``.

    ``noise = NoiseModel(meas_std, Q_c, P0)`` with every entry explicit, or
    ``NoiseModel.for_system(system, measurement_std=1e-3, process_std=1e-2, P0=100.0)``.

    Parameters
    ----------
    meas_std : sequence of N sequences of p_i floats
        Standard deviation of the noise of each output row of each channel (> 0).
    Q_c : (n, n) array_like
        Continuous-time process noise intensity (symmetric PSD).
    P0 : float, (n,) or (n, n) array_like
        Initial error covariance (symmetric PSD; a scalar p means p I, a vector the diagonal).

    Raises
    ------
    NoiseModelError
        A std that is not a finite number > 0 (booleans refused), ``Q_c`` or ``P0`` of the
        wrong shape, non-finite, non-symmetric or not PSD.
    """

    meas_std: tuple[tuple[float, ...], ...]
    Q_c: np.ndarray
    P0: np.ndarray

    def __init__(self, meas_std: Sequence[Sequence[float]], Q_c: Any, P0: Any) -> None:
        if isinstance(meas_std, np.ndarray):
            meas_std = meas_std.tolist()
        if not isinstance(meas_std, (list, tuple)) or not meas_std or not all(
            isinstance(c, (list, tuple, np.ndarray)) for c in meas_std
        ):
            raise NoiseModelError("meas_std must be a list with one list of row stds per channel")
        p = [len(c) for c in meas_std]
        std = _meas_std(meas_std, p, "meas_std")
        Qa = _array(Q_c, "Q_c")
        if Qa.ndim != 2 or Qa.shape[0] != Qa.shape[1] or Qa.shape[0] == 0:
            raise NoiseModelError(f"Q_c must be a non-empty square matrix; got shape {Qa.shape}")
        n = Qa.shape[0]
        Q = _psd(Qa, n, "Q_c")
        P = _psd(P0, n, "P0")
        for M in (Q, P):
            M.setflags(write=False)
        object.__setattr__(self, "meas_std", std)
        object.__setattr__(self, "Q_c", Q)
        object.__setattr__(self, "P0", P)

    # ------------------------------------------------------------ building
    @classmethod
    def for_system(
        cls,
        system: Any,
        *,
        measurement_std: Any = DEFAULT_MEAS_STD,
        process_std: Any = None,
        process_intensity: Any = None,
        P0: Any = DEFAULT_P0,
    ) -> NoiseModel:
        """Expand the short forms for ``system`` (an :class:`~switchobs_core.model.system.LTISystem`).

        ``measurement_std``: scalar, one per channel, or per row (module docstring).
        ``process_std`` q gives ``Q_c = q^2 I``; ``process_intensity`` is ``Q_c`` itself
        (scalar q gives ``q I``, a vector the diagonal); at most one of them; neither gives
        ``Q_c = DEFAULT_PROCESS_STD**2 I``. ``P0``: scalar (``p I``), vector or matrix.
        """
        n, p = int(system.n), tuple(int(v) for v in system.p)
        std = _meas_std(measurement_std, p, "measurement_std")
        if process_std is not None and process_intensity is not None:
            raise NoiseModelError("give process_std or process_intensity, not both")
        if process_intensity is not None:
            Q = _psd(process_intensity, n, "process_intensity")
        else:
            q = DEFAULT_PROCESS_STD if process_std is None else process_std
            if _array(q, "process_std").ndim != 0:
                raise NoiseModelError(f"process_std must be one number q (Qc = q^2 I); got {q!r}")
            Q = _psd(q, n, "process_std", square_scalar=True)
        return cls(std, Q, _psd(P0, n, "P0"))

    @classmethod
    def from_mapping(
        cls,
        spec: Mapping[str, Any] | None,
        system: Any,
        *,
        meas_std: Any = None,
        process_q: float | None = None,
        source: str = "noise",
    ) -> NoiseModel:
        """The ``noise:`` mapping of a system YAML (module docstring), then the CLI overrides.

        ``meas_std`` replaces ``measurement_std``; ``process_q`` replaces the process entry
        with ``Q_c = process_q^2 I`` (``--process-noise``). ``spec=None`` means all defaults.
        """
        if spec is None:
            spec = {}
        if not isinstance(spec, Mapping):
            raise NoiseModelError(f"{source} must be a mapping with keys {', '.join(NOISE_KEYS)}; got {spec!r}")
        unknown = sorted(set(spec) - set(NOISE_KEYS))
        if unknown:
            raise NoiseModelError(f"{source}: unknown key(s) {unknown}; allowed: {', '.join(NOISE_KEYS)}")
        kw: dict[str, Any] = {
            "measurement_std": spec.get("measurement_std", DEFAULT_MEAS_STD),
            "process_std": spec.get("process_std"),
            "process_intensity": spec.get("process_intensity"),
            "P0": spec.get("P0", DEFAULT_P0),
        }
        if meas_std is not None:
            kw["measurement_std"] = meas_std
        if process_q is not None:
            kw["process_std"], kw["process_intensity"] = process_q, None
        try:
            return cls.for_system(system, **kw)
        except NoiseModelError as err:
            raise NoiseModelError(f"{source}: {err}") from None

    # ------------------------------------------------------------ accessors
    @property
    def n(self) -> int:
        """Number of states."""
        return self.Q_c.shape[0]

    @property
    def N(self) -> int:
        """Number of channels."""
        return len(self.meas_std)

    @property
    def p(self) -> tuple[int, ...]:
        """Output rows p_i of each channel."""
        return tuple(len(s) for s in self.meas_std)

    def R(self, channel: int, rows: Sequence[int] | None = None) -> np.ndarray:
        """``R = diag(std^2)`` of ``rows`` (0-based, default all) of channel ``channel`` (1-based)."""
        if not isinstance(channel, (int, np.integer)) or isinstance(channel, bool) or not 1 <= channel <= self.N:
            raise NoiseModelError(f"channel must be an integer in 1..{self.N}; got {channel!r}")
        std = np.asarray(self.meas_std[channel - 1])
        if rows is not None:
            idx = list(rows)
            if any(isinstance(r, bool) or not isinstance(r, (int, np.integer)) or not 0 <= r < std.size for r in idx):
                raise NoiseModelError(
                    f"rows must be 0-based row indices in 0..{std.size - 1} of channel {channel}; got {idx}"
                )
            std = std[idx]
        return np.diag(std * std)

    def check_system(self, system: Any) -> None:
        """Raise NoiseModelError unless the sizes (n, p_1..p_N) match ``system``."""
        if self.n != system.n or self.p != tuple(system.p):
            raise NoiseModelError(
                f"noise model is for n = {self.n}, p = {self.p}; the system has n = {system.n}, p = {tuple(system.p)}"
            )

    # ------------------------------------------------------------ persistence
    def to_dict(self) -> dict[str, Any]:
        """JSON-ready explicit form (plain lists of floats); :meth:`from_dict` reads it back exactly."""
        return {
            "meas_std": [list(s) for s in self.meas_std],
            "Q_c": self.Q_c.tolist(),
            "P0": self.P0.tolist(),
        }

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> NoiseModel:
        """Inverse of :meth:`to_dict`."""
        if not isinstance(d, Mapping) or set(d) != {"meas_std", "Q_c", "P0"}:
            raise NoiseModelError(f"a stored noise model needs exactly the keys meas_std, Q_c, P0; got {d!r:.80}")
        return cls(d["meas_std"], d["Q_c"], d["P0"])

    def fingerprint(self) -> str:
        """SHA-256 (hex) of the explicit model (float64 little-endian bytes and shapes)."""
        h = hashlib.sha256()
        h.update(json.dumps(self.p).encode())
        for s in self.meas_std:
            h.update(np.asarray(s, dtype="<f8").tobytes())
        for M in (self.Q_c, self.P0):
            h.update(np.asarray(M.shape, dtype="<i8").tobytes())
            h.update(np.ascontiguousarray(M, dtype="<f8").tobytes())
        return h.hexdigest()

    def describe(self) -> str:
        """One line: the row stds' range, trace(Q_c)/n and trace(P0)/n."""
        flat = [v for s in self.meas_std for v in s]
        return (
            f"noise: measurement std {min(flat):g}..{max(flat):g}, Q_c trace/n = {np.trace(self.Q_c) / self.n:g}, "
            f"P0 trace/n = {np.trace(self.P0) / self.n:g}"
        )


def default_noise(system: Any) -> NoiseModel:
    """Default noise model for ``system``.

    Measurement std ``DEFAULT_MEAS_STD`` = 1 mm on every output row (for the camera
    scenarios every row is a position in metres), process intensity
    ``Q_c = DEFAULT_PROCESS_STD^2 I = 1e-4 I`` (a small random walk on every state: it keeps
    the gains from decaying to zero, as they would with ``Q_c = 0``), and a vague prior
    ``P0 = DEFAULT_P0 I = 100 I``.
    """
    return NoiseModel.for_system(system)
