"""switchobs_ros: the ROS 2 nodes of switchobs (thin glue: parameters, topics, QoS, clocks,
diagnostics; no estimation math -- that is switchobs_core).

Executables: ``estimator`` (:mod:`switchobs_ros.estimator`), ``camera_sim``
(:mod:`switchobs_ros.camera_sim`), ``managed_estimator``; their console scripts are in
:mod:`switchobs_ros.entry` (a Ctrl-C during the imports is a quiet stop). The demo runner is
``python -m tools.demo``.
"""
