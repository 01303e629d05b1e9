"""switchobs_core: switched Luenberger observers for systems whose outputs are
available one channel at a time (pure numerics, no ROS).

The mathematics follows ``shared/paper/switching-observers.tex`` (Sakha and
Kamalapurkar, "Switching Observers for Linear Systems: Beyond Individual
Observability"); equations are cited by their label in that paper, e.g.
``e:eta1_fixed``.
"""

__version__ = "0.1.0"
