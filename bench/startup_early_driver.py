#!/usr/bin/env python
"""The estimator started with its DDS participant created before the heavy imports (an experiment of
``bench/bench_startup.py --early``, not how the node starts).

``python bench/startup_early_driver.py --ros-args ...``: ``rclpy.init``, then a bare node (no parameter
services, no rosout), whose creation makes the context's DDS participant, so discovery runs while the
estimator's modules are imported and its table loaded; then :class:`~switchobs_ros.estimator.EstimatorNode`
in the same context, the bare node destroyed once it exists, and the spin of
:func:`~switchobs_ros.runner.run_node` (single-threaded executor; no start-up refusal handling: a
benchmark, not the node's entry point).
"""

from __future__ import annotations

import sys

import rclpy
from rclpy.node import Node

from switchobs_ros.ros_args import with_float_lists

rclpy.init(args=with_float_lists(sys.argv))
boot = Node("estimator_boot", start_parameter_services=False, enable_rosout=False)

import rclpy.executors  # noqa: E402

from switchobs_core.threads import single_threaded_blas  # noqa: E402
from switchobs_ros import params_files  # noqa: E402
from switchobs_ros.estimator import EstimatorNode  # noqa: E402

single_threaded_blas()
params_files.GLOBAL_FILES[:] = params_files.params_files(sys.argv)
node = EstimatorNode()
boot.destroy_node()
executor = rclpy.executors.SingleThreadedExecutor()
executor.add_node(node)
try:
    executor.spin()
except KeyboardInterrupt:
    pass
finally:
    node.destroy_node()
    rclpy.try_shutdown()
