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
"""

import sys as _sys

from . import (
    bounds,
    certificate,
    design,
    exceptions,
    families,
    model,
    numerics,
    paper,  # noqa: F401  (the paper's numbers: so.paper.TABLE)
    runtime,
    sim,
    table,
    threads,
    validation,
)
from ._version import __version__
from .bounds import envelope, rigorous
from .bounds.envelope import *  # noqa: F403
from .bounds.rigorous import *  # noqa: F403
from .certificate import *  # noqa: F403
from .design import kalman, lmi, plan, riccati, synthesis
from .design.kalman import *  # noqa: F403
from .design.lmi import *  # noqa: F403
from .design.plan import *  # noqa: F403
from .design.riccati import *  # noqa: F403
from .design.synthesis import *  # noqa: F403
from .exceptions import *  # noqa: F403
from .families import *  # noqa: F403
from .model import decomposition, noise, scenarios, schedule, system
from .model.decomposition import *  # noqa: F403
from .model.noise import *  # noqa: F403
from .model.scenarios import *  # noqa: F403
from .model.schedule import *  # noqa: F403
from .model.system import *  # noqa: F403
from .numerics import kalman_step, propagation
from .numerics.kalman_step import *  # noqa: F403
from .numerics.propagation import *  # noqa: F403
from .runtime import cycles, kalman_online, observer
from .runtime.cycles import *  # noqa: F403
from .runtime.families import base as family_base
from .runtime.families import kalman as family_kalman
from .runtime.families import lmi as family_lmi
from .runtime.families import online as family_online
from .runtime.families.base import *  # noqa: F403
from .runtime.families.kalman import *  # noqa: F403
from .runtime.families.lmi import *  # noqa: F403
from .runtime.families.online import *  # noqa: F403
from .runtime.kalman_online import *  # noqa: F403
from .runtime.observer import *  # noqa: F403
from .sim import plant
from .sim import result as sim_result
from .sim.plant import *  # noqa: F403
from .sim.result import *  # noqa: F403
from .sim.simulate import *  # noqa: F403
from .table import gains
from .table import kalman as table_kalman
from .table.gains import *  # noqa: F403
from .table.kalman import *  # noqa: F403
from .threads import *  # noqa: F403
from .validation import *  # noqa: F403

# ``so.simulate`` stays the module (``from switchobs_core import simulate`` keeps working);
# run a simulation with ``so.simulate.simulate(...)``.
simulate = _sys.modules[f"{__name__}.sim.simulate"]

#: The subpackages, in the order of their layers (docs/architecture.md): lower ones never import higher ones.
SUBPACKAGES = (numerics, model, bounds, certificate, table, design, runtime, sim)

#: Every module whose ``__all__`` is re-exported here.
MODULES = (rigorous, envelope, _sys.modules[f"{__name__}.certificate"], cycles, decomposition, lmi, exceptions,
           families, family_base, family_kalman, family_lmi, family_online, gains, kalman, kalman_online, kalman_step,
           noise, observer, plan, plant, propagation, riccati, scenarios, schedule, sim_result, simulate, synthesis,
           system, table_kalman, threads, validation)

__all__ = ["__version__", *(name for m in MODULES for name in m.__all__ if name not in ("simulate",))]
