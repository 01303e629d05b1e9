"""The message definitions and type hashes an output bag's connections declare, without rosbags' type store.

A rosbag2 connection names its type's full message definition (``msgdef``, every nested type's text) and
its RIHS01 hash; rosbags makes both from a type store (``get_typestore(Stores.ROS2_JAZZY)``: 162 message
classes built at its import, 70-90 ms of a ``switchobs_bag estimate`` start). The types a bag tool writes
are few and fixed (:data:`TYPES`: the estimator's inputs and outputs), so their two strings are kept
in :mod:`switchobs_ros.bag.msgdefs_data` as rosbags made them (``python -m switchobs_ros.bag.msgdefs``
writes that module again); :func:`definition` hands them out when the installed
rosbags is that version, and None otherwise (the caller asks the type store). ``test_msgdefs.py``
checks them against the type store's.
"""

from __future__ import annotations

import sys
from pathlib import Path

__all__ = ["TYPES", "definition", "generated"]

#: The types kept: the inputs a bag may hold (msg_bridge.SUPPORTED_TYPES, the channel's, the clock) and the
#: estimator's outputs (arrays, odometries, the typed messages, diagnostics).
TYPES = ("diagnostic_msgs/msg/DiagnosticArray", "geometry_msgs/msg/AccelStamped", "geometry_msgs/msg/PointStamped",
         "geometry_msgs/msg/PoseStamped", "geometry_msgs/msg/PoseWithCovarianceStamped",
         "geometry_msgs/msg/TwistStamped", "nav_msgs/msg/Odometry", "rosgraph_msgs/msg/Clock",
         "std_msgs/msg/Float64MultiArray", "std_msgs/msg/UInt8", "switchobs_msgs/msg/ActiveChannel",
         "switchobs_msgs/msg/ErrorBounds", "switchobs_msgs/msg/StateEstimate")

_installed: str | None = None


def definition(type_name: str) -> tuple[str, str] | None:
    """``(msgdef, rihs01)`` of ``type_name`` as the installed rosbags' Jazzy type store makes them (with the
    switchobs_msgs types registered), or None where it is not kept or another rosbags is installed."""
    global _installed
    if _installed is None:
        from importlib.metadata import version
        _installed = version("rosbags")
    from .msgdefs_data import DEFINITIONS, ROSBAGS

    if _installed != ROSBAGS:
        return None
    return DEFINITIONS.get(type_name)


def generated(types: tuple[str, ...] = TYPES) -> dict[str, tuple[str, str]]:
    """``{type: (msgdef, rihs01)}`` from rosbags' Jazzy type store (the switchobs_msgs types registered)."""
    from rosbags.typesys import Stores, get_typestore

    from msg_bridge.typed import register_rosbags_types

    store = get_typestore(Stores.ROS2_JAZZY)
    register_rosbags_types(store)
    return {t: (store.generate_msgdef(t, ros_version=2)[0], store.hash_rihs01(t)) for t in types}


def write_data(path: Path | None = None) -> None:
    """:mod:`switchobs_ros.bag.msgdefs_data` (or ``path``) made again by the installed rosbags."""
    from importlib.metadata import version

    path = Path(__file__).with_name("msgdefs_data.py") if path is None else path
    lines = ['"""The definitions :mod:`switchobs_ros.bag.msgdefs` hands out, written by ``python -m '
             'switchobs_ros.bag.msgdefs``."""', "", "#: rosbags' version that made :data:`DEFINITIONS`.",
             f"ROSBAGS = {version('rosbags')!r}", "", "#: ``{type: (msgdef, rihs01)}``.",
             "DEFINITIONS: dict[str, tuple[str, str]] = {"]
    for t, (msgdef, h) in generated().items():
        lines.append(f"    {t!r}: (")
        lines += [f"        {chunk!r}" for chunk in msgdef.splitlines(keepends=True)]
        lines.append(f"        , {h!r}),")
    lines.append("}")
    path.write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    write_data()
    sys.exit(0)
