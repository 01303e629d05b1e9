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
"""

import sys as _sys

from . import (
    bound,
    certificate,
    cycles,
    decomposition,
    design,
    envelope,
    exceptions,
    families,
    family_base,
    family_kalman,
    family_lmi,
    family_online,
    gains,
    kalman,
    kalman_online,
    noise,
    observer,
    paper,  # noqa: F401  (the paper's numbers: so.paper.TABLE)
    plan,
    plant,
    propagation,
    riccati,
    scenarios,
    schedule,
    simulate,
    synthesis,
    system,
    threads,
    validation,
)
from ._version import __version__
from .bound import *  # noqa: F403
from .certificate import *  # noqa: F403
from .cycles import *  # noqa: F403
from .decomposition import *  # noqa: F403
from .design import *  # noqa: F403
from .envelope import *  # noqa: F403
from .exceptions import *  # noqa: F403
from .families import *  # noqa: F403
from .family_base import *  # noqa: F403
from .family_kalman import *  # noqa: F403
from .family_lmi import *  # noqa: F403
from .family_online import *  # noqa: F403
from .gains import *  # noqa: F403
from .kalman import *  # noqa: F403
from .kalman_online import *  # noqa: F403
from .noise import *  # noqa: F403
from .observer import *  # noqa: F403
from .plan import *  # noqa: F403
from .plant import *  # noqa: F403
from .propagation import *  # noqa: F403
from .riccati import *  # noqa: F403
from .scenarios import *  # noqa: F403
from .schedule import *  # noqa: F403
from .simulate import *  # noqa: F403
from .synthesis import *  # noqa: F403
from .system import *  # noqa: F403
from .threads import *  # noqa: F403
from .validation import *  # noqa: F403

# ``so.simulate`` stays the module (``from switchobs_core import simulate`` keeps working);
# run a simulation with ``so.simulate.simulate(...)``.
simulate = _sys.modules[f"{__name__}.simulate"]  # noqa: F811

#: Every module whose ``__all__`` is re-exported here.
MODULES = (bound, certificate, cycles, decomposition, design, envelope, exceptions, families, family_base,
           family_kalman, family_lmi, family_online, gains, kalman, kalman_online, noise, observer, plan, plant,
           propagation, riccati, scenarios, schedule, simulate, synthesis, system, threads, validation)

__all__ = ["__version__", *(name for m in MODULES for name in m.__all__ if name not in ("simulate",))]
