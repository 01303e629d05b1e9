"""Re-verification of a loaded gain table before an observer answers with it.

A table's checksum (``payload_sha256``) catches corruption, not tampering: anyone who can write
the file can recompute it. So every table the estimator loads, from a file or from its cache,
has its designs re-checked here, cheaply (a few matrix exponentials per design), from the gains
themselves and the system, never from the numbers the file claims about them:

* every gain is finite and of the right shape (``L_i``: n x p_i; a Kalman gain: n x rows);
* LMI designs of a cycle: the exact error map over the cycle,
  ``Phi = expm((A - L_N C_N) h_N) ... expm((A - L_1 C_1) h_1)``
  (:func:`~switchobs_core.certificate.cycle_transition`), has spectral radius < 1, i.e. the
  periodic schedule of that cycle converges; a robust design is checked on the cycle at the
  centre of its residence-time box;
* Kalman designs: the period's error map ``prod_k (I - K_k H_k) Phi_k`` recomputed from the stored
  gains has spectral radius < 1. Each factor is applied as ``Phi_k M - K_k (H_k Phi_k M)`` (a rank-p
  correction instead of an n x n product), with ``Phi_k`` as a sparse matrix when at most a quarter of
  its entries are nonzero (a system of decoupled bodies); a residence whose gains and output touch
  at most half of the state, in blocks that ``Phi`` does not couple with the rest (one agent and the
  camera), is applied at once: its small product on those states, ``Phi``'s power on the others. At
  n = 132 and 1 600 phases about 12 ms (0.9 s as dense products), so the check runs at every load.

A table whose gains were all set to zero (and its checksum recomputed) runs the observer open
loop: for a system with an unstable mode its cycle map has spectral radius >= 1 and it is
refused. (For a stable ``A`` zero gains still converge, slowly: no check can tell them from a
poor design.)
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from scipy.linalg import expm
from scipy.sparse import csr_array

from ..certificate import cycle_transition
from ..certificate.paper import design_dead_time
from ..exceptions import GainTableError, SwitchobsError
from ..model.schedule import Cycle
from ..numerics.csr import csr_matmat
from .kalman import KalmanDesign

if TYPE_CHECKING:
    from ..model.system import LTISystem
    from .gains import CycleDesign, GainTable

__all__ = ["RHO_MAX", "verify_table"]

#: A design is refused when its cycle map's spectral radius is not below this.
RHO_MAX = 1.0
#: A Kalman design's sample transition is applied as a sparse matrix when at most this fraction of it is nonzero.
SPARSE_DENSITY = 0.25


def verify_table(table: GainTable, system: LTISystem, *, source: str = "gain table") -> None:
    """Raise :class:`~switchobs_core.exceptions.GainTableError` (one line, naming the design) unless
    every design of ``table`` passes the checks of the module docstring for ``system``."""
    if table.family == "kalman":
        for d in table.kalman:
            _verify_kalman(table, d, system, source)
        return
    designs = list(table.designs) + ([table.robust] if table.robust is not None else [])
    for design in designs:
        _verify_lmi(design, system, source)


def _shapes(L: np.ndarray, rows: int, cols: int, what: str, source: str) -> None:
    if L.shape != (rows, cols):
        raise GainTableError(f"{source}: {what} has shape {L.shape}; expected ({rows}, {cols})")
    if not np.isfinite(L).all():
        raise GainTableError(f"{source}: {what} has a non-finite entry")


def _verify_lmi(design: CycleDesign, system: LTISystem, source: str) -> None:
    label = design.label()
    if design.N != system.N:
        raise GainTableError(f"{source}: design {label} has {design.N} channels; the system has {system.N}")
    for i, L in enumerate(design.L):
        _shapes(np.asarray(L), system.n, system.p[i], f"design {label}, gain L_{i + 1}", source)
    if design.cycle is not None:
        h = design.cycle.h
    elif design.h_bounds is not None:
        h = (0.5 * (design.h_bounds[0] + design.h_bounds[1]),) * system.N
    else:
        return
    try:
        with np.errstate(all="ignore"):
            Phi = cycle_transition(system.A, system.C, design.L, h, design_dead_time(design))
            rho = float(np.max(np.abs(np.linalg.eigvals(Phi))))
    except (SwitchobsError, ValueError, np.linalg.LinAlgError) as err:
        raise GainTableError(f"{source}: design {label}: its cycle map cannot be computed ({err})") from None
    _check_rho(rho, f"design {label}: the error map over the cycle {Cycle(h).label()}", source)


def _verify_kalman(table: GainTable, d: dict, system: LTISystem, source: str) -> None:
    try:
        kd = table.stored_kalman(d, system)     # the design the observer reads (built once)
    except SwitchobsError as err:
        raise GainTableError(f"{source}: stored Kalman design unusable: {err}") from None
    with np.errstate(all="ignore"):
        M = _period_map(kd, system, source)
        rho = float(np.max(np.abs(np.linalg.eigvals(M)))) if np.isfinite(M).all() else float("inf")
    _check_rho(rho, f"Kalman design at {kd.rate:g} Hz: the error map over one period", source)


def _period_map(kd: KalmanDesign, system: LTISystem, source: str) -> np.ndarray:
    """``prod_k (I - K_k H_k) Phi_k`` over the design's periodic phases, from its stored gains.

    Every gain is checked first (shape, finite). The phases are then taken in runs of one channel,
    rows and step (a residence): when the run's gains and output touch only a few of the transition's
    decoupled blocks (a system of bodies, :func:`_run_states`), the run is applied at once
    (:func:`_apply_run`); otherwise phase by phase (:func:`_apply_phase`)."""
    A = np.asarray(system.A, dtype=float)
    n = system.n
    phases = kd.periodic
    gains = [np.asarray(ph.K, dtype=float) for ph in phases]
    finite = _all_finite(gains)
    outputs: dict[tuple, tuple[np.ndarray, np.ndarray | None]] = {}
    for k, ph in enumerate(phases):
        out = outputs.get((ph.channel, ph.rows))
        if out is None:
            C = np.asarray(system.C[ph.channel - 1], dtype=float)
            H = C if ph.rows is None else C[list(ph.rows)]
            out = outputs[ph.channel, ph.rows] = H, _selected(H)
        if not finite or gains[k].shape != (n, out[0].shape[0]):
            _shapes(gains[k], n, out[0].shape[0], f"Kalman design {kd.rate:g} Hz, gain of sample {k}", source)
    M = np.eye(n)
    spare = np.empty((n, n))
    steps: dict[float, tuple[np.ndarray | csr_array, np.ndarray, np.ndarray | None]] = {}
    powers: dict[tuple[float, int], csr_array] = {}
    k = 0
    while k < len(phases):
        ph = phases[k]
        end = k + 1
        while end < len(phases) and (phases[end].channel, phases[end].rows, phases[end].dt) == \
                (ph.channel, ph.rows, ph.dt):
            end += 1
        step = steps.get(ph.dt)
        if step is None:
            dense = expm(A * ph.dt)
            Phi = _transition(dense)
            step = steps[ph.dt] = Phi, dense, _blocks(Phi) if isinstance(Phi, csr_array) else None
        H, picked = outputs[ph.channel, ph.rows]
        stacked = np.stack(gains[k:end]) if end - k > 1 and step[2] is not None else None
        S = _run_states(step[2], H, stacked) if stacked is not None else None
        if S is None:
            for K in gains[k:end]:
                M, spare = _apply_phase(step[0], K, H, picked, M, spare)
        else:
            key = (ph.dt, end - k)
            if key not in powers:
                powers[key] = _block_power(step[1], step[2], end - k)
            M, spare = _apply_run(powers[key], step[1], S, H, stacked, M, spare)
        k = end
    return M


def _apply_phase(Phi: np.ndarray | csr_array, K: np.ndarray, H: np.ndarray, picked: np.ndarray | None,
                 M: np.ndarray, spare: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(I - K H) Phi M`` and the buffer left free. A sparse ``Phi`` is applied by scipy's kernel
    behind ``csr_array @ dense`` (:mod:`~switchobs_core.numerics.csr`) into ``spare``: the same products
    without about 15 us of scipy's checks. An ``H`` whose rows each read one state with weight 1
    (:func:`_selected`) is applied as those rows of the map, its product exactly for finite entries
    (a map with a non-finite entry is refused either way)."""
    if isinstance(Phi, csr_array):
        M, spare = csr_matmat(Phi.indptr, Phi.indices, Phi.data, Phi.shape, M, out=spare), M
    else:
        M = Phi @ M
    M -= K @ (M[picked] if picked is not None else H @ M)
    return M, spare


def _blocks(Phi: csr_array) -> np.ndarray:
    """The label of each state's block of ``Phi``: states coupled by a nonzero entry, either way,
    share one (the connected components of its pattern)."""
    n = Phi.shape[0]
    adj: list[set[int]] = [set() for _ in range(n)]
    for i in range(n):
        for j in Phi.indices[Phi.indptr[i]:Phi.indptr[i + 1]].tolist():
            if i != j:
                adj[i].add(j)
                adj[j].add(i)
    label = np.full(n, -1)
    for i in range(n):
        if label[i] < 0:
            label[i] = i
            todo = [i]
            while todo:
                for j in adj[todo.pop()]:
                    if label[j] < 0:
                        label[j] = i
                        todo.append(j)
    return label


def _run_states(label: np.ndarray, H: np.ndarray, gains: np.ndarray) -> np.ndarray | None:
    """The states of the transition's blocks (``label``) that a run's gains (stacked, L x n x p) write or
    its output reads (sorted), when they are at most half of the state; else None (the run is applied
    phase by phase)."""
    touched = np.any(gains != 0, axis=(0, 2)) | np.any(H != 0, axis=0)
    hit = np.zeros(label.size, dtype=bool)
    hit[label[touched]] = True
    S = np.flatnonzero(hit[label])
    return S if 2 * S.size <= label.size else None


def _block_power(dense: np.ndarray, label: np.ndarray, L: int) -> csr_array:
    """``Phi^L`` (sparse), block by block of ``Phi``'s decoupled blocks (``label``)."""
    out = np.zeros_like(dense)
    for b in np.flatnonzero(label == np.arange(label.size)):
        idx = np.flatnonzero(label == b)
        out[np.ix_(idx, idx)] = np.linalg.matrix_power(dense[np.ix_(idx, idx)], L)
    return csr_array(out)


def _apply_run(power: csr_array, dense: np.ndarray, S: np.ndarray, H: np.ndarray, gains: np.ndarray,
               M: np.ndarray, spare: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A run of phases ``(I - K_k H) Phi`` applied to ``M`` at once, when the gains write only the
    states ``S``, ``H`` reads only them and ``Phi`` does not couple them with the others (a union of
    its blocks): the rows ``S`` of the result are ``G M[S]`` with ``G = prod_k (I - K_k[S] H[:, S])
    Phi[S, S]`` (small; the product taken pairwise, later factors on the left), the others ``Phi^L M``
    (``power``). The same map in exact arithmetic."""
    P = dense[np.ix_(S, S)]
    F = P - gains[:, S, :] @ (H[:, S] @ P)      # each phase's (I - K H) Phi on S, in order
    while len(F) > 1:
        odd = F[-1:] if len(F) % 2 else None
        F = F[1::2] @ F[0:len(F) - 1:2]
        if odd is not None:
            F = np.concatenate([F, odd])
    G = F[0]
    out = csr_matmat(power.indptr, power.indices, power.data, power.shape, M, out=spare)
    out[S] = G @ M[S]
    return out, M


def _all_finite(arrays: list[np.ndarray]) -> bool:
    """Whether every entry of ``arrays`` is finite, read once per array that owns their memory (a
    table's gains are views of one array); False may also mean a non-finite number elsewhere in an
    owner, for which the caller checks each array on its own."""
    owners: dict[int, np.ndarray] = {}
    for a in arrays:
        b = a.base if isinstance(a.base, np.ndarray) and a.base.dtype == a.dtype else a
        owners.setdefault(id(b), b)
    return all(np.isfinite(b).all() for b in owners.values())


def _selected(H: np.ndarray) -> np.ndarray | None:
    """The state each row of ``H`` reads, when every row is one entry 1.0 and zeros; else None."""
    ones = H == 1.0
    if not (ones.sum(axis=1) == 1).all() or np.count_nonzero(H) != H.shape[0]:
        return None
    return np.argmax(ones, axis=1)


def _transition(Phi: np.ndarray) -> np.ndarray | csr_array:
    """``Phi`` as it is applied: sparse when at most :data:`SPARSE_DENSITY` of it is nonzero and finite."""
    if np.isfinite(Phi).all() and np.count_nonzero(Phi) <= SPARSE_DENSITY * Phi.size:
        return csr_array(Phi)
    return Phi


def _check_rho(rho: float, what: str, source: str) -> None:
    if not rho < RHO_MAX:
        raise GainTableError(f"{source}: {what} has spectral radius {rho:.4g} >= {RHO_MAX:g}: these gains do not "
                             "make the error converge (a planted or damaged table?); design it again")
