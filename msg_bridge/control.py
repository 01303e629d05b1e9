"""The control input: the topic that carries the known input ``u`` of ``xdot = A x + B u`` (e:system).

A system with inputs (``B`` with ``m > 0`` columns) takes its commands on one topic. Each message
is read into ``(stamp_ns, u)``; the estimator holds ``u`` from the message's header stamp on, until
the next command (the zero-order hold the plant sees; the observer adds its exact effect,
:meth:`switchobs_core.runtime.observer.SwitchedObserver.hold_input`). The error does not depend on
a known input, so the bounds are the same as without one.

YAML, a ``control:`` key of the system's ``inputs:`` section (``fields[k]`` is ``u[k]``, one field
per column of ``B``)::

    inputs:
      control: {topic: cmd_accel, type: geometry_msgs/AccelStamped,
                fields: [accel.linear.x, accel.linear.y]}
      sources: [...]

Any stamped type of :data:`msg_bridge.fields.SUPPORTED_TYPES` works (``geometry_msgs/TwistStamped``
for a velocity command, ``AccelStamped`` for an acceleration). Without ``control:``, a system
with inputs takes ``~/control`` (the node's private topic): a labelled ``std_msgs/Float64MultiArray``
(:func:`msg_bridge.convert.labelled_array`: the stamp in its padding) with elements
:func:`input_labels` (``u_1, ..., u_m``). ``topic`` is a relative name or ``~/<name>``.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from .fields import LABELLED_ARRAY, FieldReader
from .validate import SpecError

__all__ = ["CONTROL_TOPIC", "ControlSpec", "default_control", "input_labels", "parse_control"]

#: The default control topic (private to the estimator node).
CONTROL_TOPIC = "~/control"

_KEYS = ("topic", "type", "fields")


def input_labels(m: int) -> tuple[str, ...]:
    """The element labels of the default control message: ``u_1, ..., u_m``."""
    return tuple(f"u_{k}" for k in range(1, m + 1))


@dataclass(frozen=True)
class ControlSpec:
    """The control topic: its message type and the float64 ``fields`` that are ``u[0..m-1]``."""

    topic: str
    type: str
    fields: tuple[str, ...]
    reader: FieldReader = field(compare=False, repr=False)

    def describe(self) -> str:
        """One line: topic, type, fields -> u."""
        return f"control {self.topic} ({self.type}) {list(self.fields)} -> u[0..{len(self.fields) - 1}]"


def default_control(system: Any) -> ControlSpec | None:
    """``~/control`` (labelled array ``u_1..u_m``) for a system with inputs, None without."""
    m = int(system.m)
    if m == 0:
        return None
    labels = input_labels(m)
    return ControlSpec(CONTROL_TOPIC, LABELLED_ARRAY, labels, FieldReader(LABELLED_ARRAY, labels))


def _check_control_topic(name: Any, where: str) -> str:
    from .inputs import check_topic

    if isinstance(name, str) and name.startswith("~/"):
        check_topic(name[2:], where)
        return name
    return check_topic(name, where)


def parse_control(spec: Any, system: Any, source: str = "inputs.control") -> ControlSpec | None:
    """The :class:`ControlSpec` of a ``control:`` mapping (module docstring) for ``system``;
    None for an empty one on a system without inputs. :class:`SpecError` with one line naming
    ``source`` and what to do."""
    m = int(system.m)
    if spec is None:
        return default_control(system)
    if m == 0:
        raise SpecError(f"{source}: the system has no input (B has no columns), so it takes no commands; "
                        "remove the control key, or give the system a B")
    if not isinstance(spec, Mapping):
        raise SpecError(f"{source}: must be a mapping with keys {', '.join(_KEYS)}; got {spec!r}")
    unknown = sorted(map(str, set(spec) - set(_KEYS)))
    if unknown:
        raise SpecError(f"{source}: unknown key(s) {unknown} (known: {', '.join(_KEYS)})")
    missing = [k for k in ("type", "fields") if k not in spec]
    if missing:
        raise SpecError(f"{source}: missing key(s) {missing} (a control needs type and fields; topic defaults to "
                        f"{CONTROL_TOPIC})")
    topic = _check_control_topic(spec.get("topic", CONTROL_TOPIC), f"{source}.topic")
    try:
        reader = FieldReader(spec["type"], spec["fields"])
    except SpecError as err:
        raise SpecError(f"{source}: {err}") from None
    if len(reader.fields) != m:
        raise SpecError(f"{source}: {len(reader.fields)} field(s) for an input of m = {m} entries (the columns of "
                        "B); give one field per entry of u, in order")
    return ControlSpec(topic, reader.type, reader.fields, reader)
