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
(:mod:`switchobs_core.figures`, :mod:`switchobs_core.errorfigs`) and the command line
(:mod:`switchobs_core.cli`) are imported on their own. Importing this package does not import
cvxpy (only a design or a Lyapunov/box certificate solve does).

The re-exports are lazy (PEP 562): ``import switchobs_core`` loads no library module, a submodule
(``switchobs_core.observer``) loads just what it imports, and the first top-level name
(``so.design_table``), ``__all__`` or ``MODULES`` loads every module of :data:`MODULES` once and binds
their public names here, as an eager ``from .module import *`` of each would. A process that only
needs the observer (the estimator node, the bag tools) does not pay for the design and certificate
modules (scipy.optimize, scipy.interpolate).
"""

import importlib as _importlib

# Loaded at once, in the order the eager package had: the library's submodules import each other
# in a cycle (observer -> certificate -> simulate -> observer) that resolves only from here.
from . import bound as bound
from . import certificate as certificate
from ._version import __version__ as __version__

#: The modules whose ``__all__`` is re-exported here (by name; ``MODULES`` holds the modules).
_MODULE_NAMES = ("bound", "certificate", "cycles", "decomposition", "design", "envelope", "exceptions",
                 "families", "family_base", "family_kalman", "family_lmi", "family_online", "gains", "kalman",
                 "kalman_online", "noise", "observer", "plan", "plant", "propagation", "riccati", "scenarios",
                 "schedule", "simulate", "synthesis", "system", "threads", "validation")


def _load_all() -> None:
    """Import every module of ``_MODULE_NAMES`` and bind their public names (the eager package)."""
    g = globals()
    if "MODULES" in g:
        return
    mods = tuple(_importlib.import_module(f"{__name__}.{m}") for m in _MODULE_NAMES)
    _importlib.import_module(f"{__name__}.paper")       # the paper's numbers: so.paper.TABLE
    for m in mods:
        for name in m.__all__:
            # ``so.simulate`` stays the module (``from switchobs_core import simulate`` keeps
            # working); run a simulation with ``so.simulate.simulate(...)``.
            if name != "simulate":
                g[name] = getattr(m, name)
    g["__all__"] = ["__version__", *(name for m in mods for name in m.__all__ if name != "simulate")]
    #: Every module whose ``__all__`` is re-exported here.
    g["MODULES"] = mods


def __getattr__(name: str):
    if not name.startswith("_"):
        try:                                               # a submodule: just that one
            return _importlib.import_module(f"{__name__}.{name}")
        except ModuleNotFoundError as err:
            if err.name != f"{__name__}.{name}":
                raise
    if name == "__all__" or not name.startswith("_"):       # a re-exported name: every module
        _load_all()
        if name in globals():
            return globals()[name]
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__() -> list[str]:
    _load_all()
    return sorted(set(globals()) | set(__all__))  # noqa: F821  (bound by _load_all)
