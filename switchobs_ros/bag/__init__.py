"""Bag tools: rosbag2 bags (mcap or sqlite3, metadata version 9) through the estimator.

``switchobs_bag {generate,record,play,estimate,report,info}`` (see :mod:`.cli` and
docs/tutorials/node-and-bags.md).

Modules
-------
io        reading and writing bags (the ``rosbags`` library for the container, CDR bytes
          from/to ``rclpy.serialization``), topic/type checks, the QoS of each topic
generate  the paper's scenario through camera_sim's model, written straight to a bag (no DDS)
estimate  the estimator's pipeline (switchobs_ros.pipeline) over a bag, offline, deterministic
play      live replay with ``/clock`` (a node)
record    a recorder node: topics to a bag, receive time on the node clock
report    error against truth, the bounds, the channel; summary table
"""
