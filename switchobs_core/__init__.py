"""switchobs_core: switched Luenberger observers for systems whose outputs are
available one channel at a time (pure numerics, no ROS).

The mathematics follows Sakha and Kamalapurkar, "Switching Observers for Linear Systems:
Beyond Individual Observability". Equations are cited by their label in that paper, e.g.
``e:eta1_fixed``; every label resolves to the paper's equation, lemma, theorem or section
number in ``docs/equations.md``.

The public API of every library module is re-exported here (python-control style)::

    import switchobs_core as so
    system = so.load_system("paper")
    table = so.design_table(system, [so.Cycle.from_ts(2.0, 0.6)])
    obs = so.SwitchedObserver(system, table)

The paper's transcribed numbers stay in :mod:`switchobs_core.paper`; the figure writers
(:mod:`switchobs_core.sim.figures`, :mod:`switchobs_core.sim.errorfigs`), the simulator's
continuous-output step (:mod:`switchobs_core.sim.continuous`, behind ``simulate``) and the
command line (:mod:`switchobs_core.cli`) are imported on their own. Importing this package does not
import cvxpy (only a design or a Lyapunov/box certificate solve does).

The re-exports are made on first use (PEP 562 ``__getattr__``): ``import switchobs_core.exceptions``,
which every module of the package and of the ROS side pays, imports the package and that module
only, so a node that loads a cached table never imports the design or certificate stack (scipy's
optimisers, interpolation, ...). The first top-level name read (``so.load_system``, ``so.__all__``,
``from switchobs_core import *``) imports every re-exported module at once, as an eager package
would.
"""


import importlib as _importlib
import importlib.util as _importlib_util
import sys as _sys
from typing import Any as _Any

from ._version import __version__ as __version__

#: The subpackages and loose modules the package imports for its re-exports, in the order of the
#: layers (docs/architecture.md): lower ones never import higher ones.
_SUBMODULES = ("exceptions", "validation", "threads", "paper", "families", "numerics", "model", "bounds", "certificate",
               "table", "design", "runtime", "sim")
#: Top-level names bound to modules (``so.lmi`` is :mod:`switchobs_core.design.lmi`).
_ALIASES = {
    "envelope": "bounds.envelope", "rigorous": "bounds.rigorous",
    "kalman": "design.kalman", "lmi": "design.lmi", "plan": "design.plan", "riccati": "design.riccati",
    "synthesis": "design.synthesis",
    "decomposition": "model.decomposition", "noise": "model.noise", "scenarios": "model.scenarios",
    "schedule": "model.schedule", "system": "model.system",
    "kalman_step": "numerics.kalman_step", "propagation": "numerics.propagation",
    "cycles": "runtime.cycles", "kalman_online": "runtime.kalman_online", "observer": "runtime.observer",
    "family_base": "runtime.families.base", "family_kalman": "runtime.families.kalman",
    "family_lmi": "runtime.families.lmi", "family_online": "runtime.families.online",
    "plant": "sim.plant", "sim_result": "sim.result", "gains": "table.gains", "table_kalman": "table.kalman",
    # ``so.simulate`` is the module (``from switchobs_core import simulate`` keeps working);
    # run a simulation with ``so.simulate.simulate(...)``.
    "simulate": "sim.simulate",
}
#: Every module whose ``__all__`` is re-exported here, in the order of :data:`MODULES`.
_REEXPORTED = ("bounds.rigorous", "bounds.envelope", "certificate", "runtime.cycles", "model.decomposition",
               "design.lmi", "exceptions", "families", "runtime.families.base", "runtime.families.kalman",
               "runtime.families.lmi", "runtime.families.online", "table.gains", "design.kalman",
               "runtime.kalman_online", "numerics.kalman_step", "model.noise", "runtime.observer", "design.plan",
               "sim.plant", "numerics.propagation", "design.riccati", "model.scenarios", "model.schedule",
               "sim.result", "sim.simulate", "design.synthesis", "model.system", "table.kalman", "threads",
               "validation")
_loading = False


def _module(dotted: str) -> _Any:
    return _importlib.import_module(f"{__name__}.{dotted}")


def _load() -> None:
    """Import every re-exported module and bind its public names and the module aliases here (once;
    a call made while the imports run, by one of them, returns at once)."""
    global _loading
    if _loading:
        return
    _loading = True
    try:
        _bind()
    except BaseException:
        _loading = False        # an import failed: the next name read tries again (and raises again)
        raise


def _bind() -> None:
    global SUBPACKAGES, MODULES, __all__
    names = globals()
    for sub in _SUBMODULES:
        names[sub] = _module(sub)
    names.update({alias: _module(dotted) for alias, dotted in _ALIASES.items()})
    modules = tuple(_module(dotted) for dotted in _REEXPORTED)
    for m in modules:
        names.update({name: getattr(m, name) for name in m.__all__ if name != "simulate"})
    #: The subpackages, in the order of their layers (docs/architecture.md): lower ones never import higher ones.
    SUBPACKAGES = tuple(names[s] for s in ("numerics", "model", "bounds", "certificate", "table", "design", "runtime",
                                          "sim"))
    #: Every module whose ``__all__`` is re-exported here.
    MODULES = modules
    __all__ = ["__version__", *(name for m in MODULES for name in m.__all__ if name not in ("simulate",))]


def __getattr__(name: str) -> _Any:
    """A submodule on its own (``from switchobs_core import exceptions``); any other name after every
    re-exported module is imported (:func:`_load`)."""
    if name.startswith("__") and name != "__all__":
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    if f"{__name__}.{name}" not in _sys.modules:
        try:
            spec = _importlib_util.find_spec(f"{__name__}.{name}")
        except (ImportError, ValueError):
            spec = None
        if spec is not None:
            return _module(name)
    _load()
    try:
        return globals()[name]
    except KeyError:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}") from None


def __dir__() -> list[str]:
    _load()
    return sorted(globals())
