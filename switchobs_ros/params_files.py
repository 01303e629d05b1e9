"""Which sections of a ROS 2 params file apply to a node, and a params file that applies to none.

A params file is ``<node key>: ros__parameters: {...}``; rcl gives a node the sections whose key
matches its fully qualified name (``/robot1/estimator``). A key without a leading ``/`` is taken
from the root (``estimator`` is ``/estimator``: it does *not* match ``/robot1/estimator``), ``/*``
matches one name and ``/**`` any number of them (``/**`` every node, ``/**/estimator`` an
``estimator`` in any namespace). :func:`key_matches` reproduces that matching (checked against
rclpy's own in test/ros/test_params_namespaces.py), so the offline tools read a file as the node
does and a node can say when a file it was given applies to it nowhere: such a file would be
ignored silently by rcl (the node would run on its defaults), so the node refuses to start
(:func:`unmatched_files`), naming the file, its keys and the node's name.

The shipped files (config/*.yaml) are keyed ``/**``: they apply to the node in any namespace,
one per robot of a fleet.
"""

from __future__ import annotations

import re
from collections.abc import Iterable, Sequence
from functools import lru_cache
from pathlib import Path

import yaml

__all__ = ["GLOBAL_FILES", "key_matches", "matching_sections", "params_files", "unmatched_files"]

#: The ``--params-file`` paths of the process's ROS arguments (as given, before any rewrite):
#: recorded by :func:`switchobs_ros.runner.run_node`, checked by
#: :func:`switchobs_ros.params.declare_all`.
GLOBAL_FILES: list[str] = []


@lru_cache(maxsize=64)
def _pattern(key: str) -> re.Pattern:
    k = key if key.startswith("/") else "/" + key
    out = []
    for part in k.split("/")[1:]:
        if part == "**":
            out.append("(?:/[^/]+)*")
        elif part == "*":
            out.append("/[^/]+")
        else:
            out.append("/" + re.escape(part))
    return re.compile("".join(out) or "/")


def key_matches(key: str, fqn: str) -> bool:
    """Whether the params-file section ``key`` applies to the node named ``fqn`` (module docstring)."""
    return _pattern(str(key).rstrip("/") or "/").fullmatch(fqn) is not None


def matching_sections(doc, fqn: str) -> list[dict]:
    """The ``ros__parameters`` mappings of ``doc`` (a loaded params file) whose keys match ``fqn``,
    in file order (a later one overrides an earlier one, as in rcl)."""
    if not isinstance(doc, dict):
        return []
    return [sect["ros__parameters"] for key, sect in doc.items()
            if isinstance(sect, dict) and isinstance(sect.get("ros__parameters"), dict) and key_matches(key, fqn)]


def params_files(argv: Sequence[str]) -> list[str]:
    """The ``--params-file`` paths in the ROS arguments of ``argv``."""
    out, in_ros = [], False
    for i, a in enumerate(argv):
        if a == "--ros-args":
            in_ros = True
        elif a == "--":
            in_ros = False
        elif in_ros and i > 0 and argv[i - 1] == "--params-file":
            out.append(a)
    return out


def unmatched_files(files: Iterable[str | Path], fqn: str) -> str:
    """'' when every params file in ``files`` has a section for the node ``fqn``, else one line
    naming the files that have none, their keys, and how to key a file for any namespace.
    A file that cannot be read is left to rcl (which has refused it already)."""
    bad = []
    for f in files:
        try:
            doc = yaml.safe_load(Path(f).read_text())
        except (OSError, UnicodeDecodeError, yaml.YAMLError):
            continue
        if not matching_sections(doc, fqn):
            keys = ", ".join(repr(str(k)) for k in doc) if isinstance(doc, dict) and doc else "none"
            bad.append(f"{f} (keys: {keys})")
    if not bad:
        return ""
    return (f"params file {'; '.join(bad)} has no section for node '{fqn}': rcl would ignore it and the node would "
            f"run on its defaults. Key the section '/**' (any node) or '/**/{fqn.rsplit('/', 1)[-1]}' (this node "
            f"in any namespace), or '{fqn}'")
