"""Tooling of the repository, not installed with the package: what only the demo, the tests and
the benchmarks need.

- :mod:`tools.launch`: start a node as a subprocess (``NodeProcess``) with localhost-only DDS and
  this run's ``ROS_DOMAIN_ID``, and a collector node (there is no ``ros2 launch`` here);
- :mod:`tools.domain`: claim a free ``ROS_DOMAIN_ID`` (a lock file per id);
- :mod:`tools.demo`: the demo (``bash scripts/demo.sh``);
- :mod:`tools.live_replay`: estimator, recorder and player over DDS (tests, bench_bag).

Run from the repository root (``python -m tools.demo``); the tests have the root on their path.
"""
