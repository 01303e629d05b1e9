"""Built-in systems: the paper's camera and two agents (Sec. ``subsec:sim_model``) and its
generalization to one camera and M agents.

Each body j (camera c, agents 1..M) is a planar double integrator with velocity matrix
D_j (e:sim_Aj): chi_j = [p_x, p_y, v_x, v_y], A_j = [[0, I], [0, D_j]], and
A = blkdiag(A_c, A_1, ..., A_M) (e:sim_A_blkdiag). Channel rho measures the camera
position and the position of agent rho: y_rho = [p_c; p_rho]. Each channel alone is
unobservable and (with an unstable agent mode) not detectable; all together are
observable.

Paper labels (``e:...``, ``t:...``) resolve to numbers in ``docs/equations.md``.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ..exceptions import InvalidSystem
from ..loading import as_number
from .disturbance import Disturbance
from .noise import NoiseModel
from .system import LTISystem, read_spec

__all__ = ["paper_system", "camera_agents", "SCENARIOS", "build_scenario", "system_from_dict", "load_system",
           "load_noise", "load_disturbance", "PAPER_D"]

#: Most agents :func:`camera_agents` builds (n = 4 (M + 1) states): bounds what a file asks for.
MAX_AGENTS = 200

#: The paper's velocity matrices (Sec. ``subsec:sim_params``): D_c, D_1, D_2 diagonals.
PAPER_D: tuple[tuple[float, float], ...] = ((0.0, 0.0), (0.0, 0.2), (0.0, 0.1))


def _body(d: Sequence[float]) -> np.ndarray:
    A = np.zeros((4, 4))
    A[0, 2] = A[1, 3] = 1.0
    A[2, 2], A[3, 3] = float(d[0]), float(d[1])
    return A


def camera_agents(
    agents: int = 2,
    *,
    D_c: Sequence[float] = (0.0, 0.0),
    D_agents: Sequence[Sequence[float]] | None = None,
    name: str | None = None,
) -> LTISystem:
    """One camera and M agents, each a planar double integrator.

    ``sys = camera_agents(M, D_c=(0, 0), D_agents=[(0, 0.2), (0, 0.1), ...])``

    Parameters
    ----------
    agents : int
        M >= 2 (one channel per agent).
    D_c : (2,) sequence
        Diagonal of the camera's velocity matrix.
    D_agents : sequence of M (2,) sequences, optional
        Diagonals of the agents' velocity matrices. Default: the paper's (0, 0.2) and
        (0, 0.1) for agents 1 and 2, then (0, 0.05 + 0.05 / (j - 1)) for agent j >= 3
        (0.075, 0.067, 0.0625, ..., 0.0516 at j = 32, towards 0.05; agent 2's 0.1 is the
        same formula at j = 2): every agent has an unstable mode of the order of the paper's,
        no two agents are alike, and adding agents changes none of the others.

    What grows with M: the state (n = 4 (M + 1)), the cycle (M residences) and the time each
    agent goes unseen, ``(M - 1) h`` for residences ``h``. Over that stretch the error of an
    agent's unstable velocity grows by ``e^{d (M - 1) h}`` and its position's by about
    ``e^{d (M - 1) h} / d`` (agent 1, d = 0.2/s, grows most), and the Kalman design's periodic
    covariance spans the square of that and more: with every h = 1 s at 50 Hz, 200 at M = 2,
    2.8e4 at M = 8, 9.3e8 at M = 32. Past the limit of double precision
    (:mod:`switchobs_core.design.precision`, 1e12) the design is refused with one line: at
    10 Hz from M = 53 on (agent 1 unseen for 52 s); shorter residences carry more agents.
    """
    if isinstance(agents, (bool, np.bool_)) or not isinstance(agents, (int, np.integer, str)):
        raise InvalidSystem(f"agents must be a whole number; got {agents!r}")
    try:
        M = int(agents)
    except ValueError:
        raise InvalidSystem(f"agents must be a whole number; got {agents!r}") from None
    if M < 2:
        raise InvalidSystem(f"camera_agents needs at least 2 agents (one channel each); got {M}")
    if M > MAX_AGENTS:
        raise InvalidSystem(f"camera_agents takes at most {MAX_AGENTS} agents; got {M}")
    if D_agents is None:
        D_agents = [PAPER_D[1 + k] if k < 2 else (0.0, 0.05 + 0.05 / k) for k in range(M)]
    if not isinstance(D_c, (Sequence, np.ndarray)) or not isinstance(D_agents, (Sequence, np.ndarray)) \
            or any(not isinstance(d, (Sequence, np.ndarray)) for d in D_agents):
        raise InvalidSystem("D_c must be a pair of numbers and D_agents a list of pairs")
    D_agents = [tuple(as_number(v, f"D_agents[{k}]", exc=InvalidSystem, finite=False) for v in d)
                for k, d in enumerate(D_agents)]
    D_c = tuple(as_number(v, "D_c", exc=InvalidSystem, finite=False) for v in D_c)
    if len(D_c) != 2 or not all(math.isfinite(v) for v in D_c):
        raise InvalidSystem(f"D_c must have 2 finite entries; got {D_c}")
    if len(D_agents) != M or any(len(d) != 2 for d in D_agents):
        raise InvalidSystem(f"D_agents must hold {M} pairs (one per agent); got {D_agents}")
    bad = [k + 1 for k, d in enumerate(D_agents) if not all(math.isfinite(v) for v in d)]
    if bad:
        raise InvalidSystem(f"D_agents has a non-finite entry for agent(s) {bad}: {D_agents}")
    bodies = [_body(D_c)] + [_body(d) for d in D_agents]
    n = 4 * (M + 1)
    A = np.zeros((n, n))
    for j, Aj in enumerate(bodies):
        A[4 * j : 4 * j + 4, 4 * j : 4 * j + 4] = Aj
    Cs = []
    for rho in range(1, M + 1):
        Ci = np.zeros((4, n))
        Ci[0, 0] = Ci[1, 1] = 1.0
        Ci[2, 4 * rho] = Ci[3, 4 * rho + 1] = 1.0
        Cs.append(Ci)
    body_names = ["camera"] + [f"agent{k}" for k in range(1, M + 1)]
    labels = [f"{b}.{q}" for b in body_names for q in ("p_x", "p_y", "v_x", "v_y")]
    outputs = [("camera.p_x", "camera.p_y", f"agent{k}.p_x", f"agent{k}.p_y") for k in range(1, M + 1)]
    return LTISystem(
        A,
        None,
        Cs,
        name=name
        or (
            "paper" if M == 2 and list(D_agents) == list(PAPER_D[1:]) and tuple(D_c) == (0, 0) else f"camera_{M}_agents"
        ),
        state_labels=labels,
        channel_names=[f"agent{k}" for k in range(1, M + 1)],
        output_labels=outputs,
    )


def paper_system() -> LTISystem:
    """The paper's 12-state camera/two-agent model with D_1 = diag(0, 0.2), D_2 = diag(0, 0.1)."""
    return camera_agents(2, D_c=PAPER_D[0], D_agents=PAPER_D[1:], name="paper")


SCENARIOS: dict[str, Callable[..., LTISystem]] = {
    "paper": paper_system,
    "camera_agents": camera_agents,
}


def build_scenario(name: str, /, **params: Any) -> LTISystem:
    """Build a built-in scenario by name with its keyword parameters."""
    if name not in SCENARIOS:
        raise InvalidSystem(f"unknown scenario {name!r}; built-in scenarios: {', '.join(sorted(SCENARIOS))}")
    try:
        return SCENARIOS[name](**params)
    except TypeError as err:
        raise InvalidSystem(f"scenario '{name}': bad parameters ({err})") from None


def system_from_dict(spec: Any, *, source: str = "<dict>") -> LTISystem:
    """A system from a parsed YAML mapping: ``scenario: name`` with the scenario's
    parameters, or the explicit schema of :meth:`LTISystem.from_dict`."""
    if isinstance(spec, dict) and ("noise" in spec or "inputs" in spec or "disturbance" in spec):
        # the noise model is read by load_noise, the disturbance by load_disturbance, the input
        # specifications by msg_bridge.inputs
        spec = {k: v for k, v in spec.items() if k not in ("noise", "inputs", "disturbance")}
    if isinstance(spec, dict) and "scenario" in spec:
        params = {k: v for k, v in spec.items() if k != "scenario"}
        if any(not isinstance(k, str) for k in params):
            raise InvalidSystem(f"{source}: scenario parameters must be named by strings; got "
                                f"{sorted(map(repr, params))}")
        try:
            return build_scenario(str(spec["scenario"]), **params)
        except InvalidSystem as err:
            if source == "<dict>":
                raise
            raise type(err)(f"{source}: {err}") from None
    return LTISystem.from_dict(spec, source=source)


def _section(spec: str | Path, key: str) -> tuple[Any, str]:
    """The ``key:`` mapping of a system file and its name for messages (None for a built-in scenario)."""
    s = str(spec)
    if s not in SCENARIOS:
        data = read_spec(Path(s))
        if isinstance(data, dict):
            return data.get(key), f"{s}: {key}"
    return None, key


def load_noise(spec: str | Path, system: LTISystem, *, meas_std: Any = None,
               process_q: float | None = None, disturbance: Disturbance | None = None) -> NoiseModel:
    """The noise model of a system: the ``noise:`` mapping of its YAML file (defaults for a
    built-in scenario or a file without one, :func:`switchobs_core.model.noise.default_noise`),
    then the command-line overrides ``meas_std`` (``--meas-noise``) and ``process_q``
    (``--process-noise``); see :meth:`NoiseModel.from_mapping`. With an active ``disturbance`` and
    no process noise given, ``Q_c`` is its :meth:`~switchobs_core.model.disturbance.Disturbance.intensity`."""
    mapping, source = _section(spec, "noise")
    if (disturbance is not None and disturbance.active and process_q is None
            and not (isinstance(mapping, dict) and ({"process_std", "process_intensity"} & set(mapping)))):
        mapping = {**(mapping if isinstance(mapping, dict) else {}), "process_intensity": disturbance.intensity()}
    return NoiseModel.from_mapping(mapping, system, meas_std=meas_std, process_q=process_q, source=source)


def load_disturbance(spec: str | Path, system: LTISystem, *, w_max: Any = None) -> Disturbance:
    """The declared disturbance of a system: the ``disturbance:`` mapping of its YAML file (a
    built-in scenario or a file without one: unit accelerations on the velocity states, no bound),
    then the override ``w_max`` (``disturbance.max``: one number or q; None or empty: keep)."""
    mapping, source = _section(spec, "disturbance")
    dist = Disturbance.from_mapping(mapping, system, source=source)
    if w_max is None or (isinstance(w_max, (list, tuple)) and not w_max):
        return dist
    if dist.q == 0:
        raise InvalidSystem(f"disturbance.max is given but the system declares no disturbance input: add "
                            f"'disturbance: {{B_w: <n x q>}}' to {spec} (no state is labelled as a velocity)")
    return dist.with_max(w_max)


def load_system(spec: str | Path) -> LTISystem:
    """A built-in scenario by name (``paper``, ``camera_agents``, ...) or a YAML file path."""
    s = str(spec)
    if s in SCENARIOS:
        return build_scenario(s)
    path = Path(s)
    if path.suffix.lower() in (".yaml", ".yml", ".json") or path.exists():
        if not path.exists():
            raise InvalidSystem(f"system file {path} does not exist")
        return system_from_dict(read_spec(path), source=str(path))
    raise InvalidSystem(f"unknown scenario '{s}' and no such file; built-in scenarios: {', '.join(sorted(SCENARIOS))}")
