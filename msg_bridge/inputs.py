"""TEMPORARY stand-in (replaced by the input-specification module of branch i19-specs)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any


class SpecError(ValueError):
    pass


@dataclass(frozen=True)
class InputSource:
    topic: str
    type: str
    fields: tuple
    rows: tuple
    channel: Any
    reader: Any = None


@dataclass(frozen=True)
class InputSpecs:
    sources: tuple
    channel_topic: Any
    uncovered: tuple = field(default=())

    def describe(self) -> str:
        return "; ".join(f"{s.topic}" for s in self.sources)


def load_inputs(system_param: str, system: Any, *, camera_body: str = "camera", override: str = "") -> InputSpecs:
    from switchobs_ros.core_config import camera_target_rows
    rows = camera_target_rows(system, camera_body)
    (cam, tgt) = rows[0]
    f = ("pose.position.x", "pose.position.y")
    return InputSpecs((InputSource("camera/pose", "geometry_msgs/msg/PoseStamped", f, cam, None),
                       InputSource("target/pose", "geometry_msgs/msg/PoseStamped", f, tgt, None)),
                      "camera/active_channel")


def message_class(type_name: str):
    import importlib
    pkg, _, name = type_name.replace("/msg/", "/").partition("/")
    return getattr(importlib.import_module(f"{pkg}.msg"), name)
