"""The message definitions and type hashes an output bag's connections declare, without rosbags' type store.

A rosbag2 connection names its type's full message definition (``msgdef``, every nested type's text) and
its RIHS01 hash; rosbags makes both from a type store (``get_typestore(Stores.ROS2_JAZZY)``: 162 message
classes built at its import, 70-90 ms of a ``switchobs_bag estimate`` start). The types a bag tool writes
are few and fixed (:data:`TYPES`: the estimator's inputs and outputs), so their two strings are kept
in :mod:`switchobs_ros.bag.msgdefs_data` as rosbags made them (``python -m switchobs_ros.bag.msgdefs``
writes that module again), with the sha256 of the installed switchobs_msgs ``.msg`` files they were made
from. :func:`definition` hands them out when the installed rosbags is that version, and, for a
switchobs_msgs type, when the installed ``.msg`` files have that digest (a changed and rebuilt
switchobs_msgs declares its new definition); None otherwise (the caller asks the type store:
:func:`typestore`). ``test_msgdefs.py`` checks them against the type store's.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

__all__ = ["TYPES", "definition", "from_store", "generated", "msgs_digest", "typestore"]

#: The types kept: the inputs a bag may hold (msg_bridge.SUPPORTED_TYPES, the channel's, the clock) and the
#: estimator's outputs (arrays, odometries, the typed messages, diagnostics).
TYPES = ("diagnostic_msgs/msg/DiagnosticArray", "geometry_msgs/msg/AccelStamped", "geometry_msgs/msg/PointStamped",
         "geometry_msgs/msg/PoseStamped", "geometry_msgs/msg/PoseWithCovarianceStamped",
         "geometry_msgs/msg/TwistStamped", "nav_msgs/msg/Odometry", "rosgraph_msgs/msg/Clock",
         "std_msgs/msg/Float64MultiArray", "std_msgs/msg/UInt8", "switchobs_msgs/msg/ActiveChannel",
         "switchobs_msgs/msg/ErrorBounds", "switchobs_msgs/msg/StateEstimate")

_OWN = "switchobs_msgs/"

#: Whether the kept definitions hold for the installed rosbags and the installed switchobs_msgs (None: not
#: asked yet; the digest is taken only when a switchobs_msgs type is asked for).
_valid: dict[bool, bool | None] = {False: None, True: None}


def msgs_digest() -> str:
    """sha256 of the installed switchobs_msgs ``.msg`` files the type store reads (names and texts)."""
    from msg_bridge.typed import msg_files

    h = hashlib.sha256()
    for name, path in msg_files():
        h.update(name.encode() + b"\0" + path.read_bytes() + b"\0")
    return h.hexdigest()


def definition(type_name: str) -> tuple[str, str] | None:
    """``(msgdef, rihs01)`` of ``type_name`` as the installed rosbags' Jazzy type store makes them (with the
    switchobs_msgs types registered), or None where it is not kept, another rosbags is installed (or none),
    or, for a switchobs_msgs type, the installed ``.msg`` files are not those the kept ones were made from."""
    from .msgdefs_data import DEFINITIONS, ROSBAGS, SWITCHOBS_MSGS

    own = type_name.startswith(_OWN)
    valid = _valid[own]
    if valid is None:
        if _valid[False] is None:
            from importlib.metadata import PackageNotFoundError, version
            try:
                _valid[False] = version("rosbags") == ROSBAGS
            except PackageNotFoundError:
                _valid[False] = False
        valid = _valid[own] = _valid[False] and (not own or msgs_digest() == SWITCHOBS_MSGS)
    if not valid:
        return None
    return DEFINITIONS.get(type_name)


def typestore():
    """rosbags' Jazzy type store with the switchobs_msgs types registered."""
    from rosbags.typesys import Stores, get_typestore

    from msg_bridge.typed import register_rosbags_types

    store = get_typestore(Stores.ROS2_JAZZY)
    register_rosbags_types(store)
    return store


def from_store(store, type_name: str) -> tuple[str, str]:
    """``(msgdef, rihs01)`` of ``type_name`` from a type store."""
    return store.generate_msgdef(type_name, ros_version=2)[0], store.hash_rihs01(type_name)


def generated(types: tuple[str, ...] = TYPES) -> dict[str, tuple[str, str]]:
    """``{type: (msgdef, rihs01)}`` from rosbags' Jazzy type store (the switchobs_msgs types registered)."""
    store = typestore()
    return {t: from_store(store, t) for t in types}


def write_data(path: Path | None = None) -> None:
    """:mod:`switchobs_ros.bag.msgdefs_data` (or ``path``) made again by the installed rosbags, from the
    installed switchobs_msgs (its digest recorded)."""
    from importlib.metadata import version

    path = Path(__file__).with_name("msgdefs_data.py") if path is None else path
    lines = ['"""The definitions :mod:`switchobs_ros.bag.msgdefs` hands out, written by ``python -m '
             'switchobs_ros.bag.msgdefs``."""', "", "#: rosbags' version that made :data:`DEFINITIONS`.",
             f"ROSBAGS = {version('rosbags')!r}",
             "#: sha256 of the switchobs_msgs .msg files they were made from (msgdefs.msgs_digest).",
             f"SWITCHOBS_MSGS = {msgs_digest()!r}", "", "#: ``{type: (msgdef, rihs01)}``.",
             "DEFINITIONS: dict[str, tuple[str, str]] = {"]
    for t, (msgdef, h) in generated().items():
        lines.append(f"    {t!r}: (")
        lines += [f"        {chunk!r}" for chunk in msgdef.splitlines(keepends=True)]
        lines.append(f"        , {h!r}),")
    lines.append("}")
    path.write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    write_data()
