"""Declared parameters: one table per node, declared with descriptions, read and checked once.

A node's parameters are listed as :class:`Param` entries (name, default, description). The
table is the single source of the parameter reference of the documentation site
(``tools/docs_gen.py`` renders it). :func:`declare_all` declares them on a node with a
``ParameterDescriptor`` and returns their values; a wrong type or a parameter in the params
file that the node does not know raises :class:`ConfigError` (the node refuses to start), and so
does a params file of the process's ROS arguments that has no section for the node
(:func:`switchobs_ros.params_files.unmatched_files`: rcl would ignore it silently).
"""

from __future__ import annotations

import difflib
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

from rcl_interfaces.msg import ParameterDescriptor, ParameterType
from rclpy.exceptions import (
    InvalidParameterTypeException,
    ParameterUninitializedException,
)
from rclpy.node import Node
from rclpy.parameter import Parameter

from switchobs_core.exceptions import SwitchobsError

from . import params_files

__all__ = ["ConfigError", "Param", "declare_all", "unknown_parameters"]


class ConfigError(SwitchobsError, ValueError):
    """A bad configuration: the node logs one line and exits non-zero."""


_TYPES = {
    bool: ParameterType.PARAMETER_BOOL,
    int: ParameterType.PARAMETER_INTEGER,
    float: ParameterType.PARAMETER_DOUBLE,
    str: ParameterType.PARAMETER_STRING,
}
_ARRAY_TYPES = {
    float: ParameterType.PARAMETER_DOUBLE_ARRAY,
    int: ParameterType.PARAMETER_INTEGER_ARRAY,
    str: ParameterType.PARAMETER_STRING_ARRAY,
}
_TYPE_NAMES = {
    ParameterType.PARAMETER_BOOL: "bool", ParameterType.PARAMETER_INTEGER: "integer",
    ParameterType.PARAMETER_DOUBLE: "double", ParameterType.PARAMETER_STRING: "string",
    ParameterType.PARAMETER_DOUBLE_ARRAY: "double array",
    ParameterType.PARAMETER_INTEGER_ARRAY: "integer array",
    ParameterType.PARAMETER_STRING_ARRAY: "string array",
}


@dataclass(frozen=True)
class Param:
    """One parameter: ``name``, ``default`` (its type is the parameter's), ``description``.

    For an array parameter, ``default`` is a tuple and ``item`` the element type (needed when
    the default is empty).
    """

    name: str
    default: Any
    description: str
    item: type | None = None
    read_only: bool = True

    @property
    def type(self) -> int:
        if isinstance(self.default, tuple):
            item = self.item or type(self.default[0])
            return _ARRAY_TYPES[item]
        return _TYPES[type(self.default)]

    @property
    def type_name(self) -> str:
        return _TYPE_NAMES[self.type]


def _coerce_override(overrides: dict, p: Param) -> None:
    """Make harmless overrides fit the declared type, refuse empty ones (one line each):

    - an integer for a double parameter (``-p e0:=5``), or integers for a double array, is
      the same number: it is converted instead of refused;
    - an empty list (``tau: []`` in a params file, which rcl reads as "not set") for a
      parameter whose default is not empty is refused, not silently replaced by the default.
    """
    ov = overrides.get(p.name)
    if ov is None:
        return
    if ov.type_ == Parameter.Type.NOT_SET and isinstance(p.default, tuple) and p.default:
        raise ConfigError(f"parameter '{p.name}' is empty; give at least one value, or leave it out for the "
                          f"default {list(p.default)}")
    if p.type == ParameterType.PARAMETER_DOUBLE and ov.type_ == Parameter.Type.INTEGER:
        overrides[p.name] = Parameter(p.name, Parameter.Type.DOUBLE, float(ov.value))
    elif p.type == ParameterType.PARAMETER_DOUBLE_ARRAY and ov.type_ == Parameter.Type.INTEGER_ARRAY:
        overrides[p.name] = Parameter(p.name, Parameter.Type.DOUBLE_ARRAY, [float(x) for x in ov.value])
    elif p.type == ParameterType.PARAMETER_DOUBLE_ARRAY and ov.type_ in (Parameter.Type.DOUBLE, Parameter.Type.INTEGER):
        overrides[p.name] = Parameter(p.name, Parameter.Type.DOUBLE_ARRAY, [float(ov.value)])   # one number: [it]


def declare_all(node: Node, params: list[Param], *, gated: bool = False) -> dict[str, Any]:
    """Declare ``params`` on ``node``; return ``{name: value}``.

    ``gated``: declare every parameter writable; the node's on-set-parameters callback decides
    (and says why it refuses one). Otherwise ``Param.read_only`` is declared as is.

    Raises
    ------
    ConfigError
        A parameter of the wrong type in the params file or on the command line, or a
        parameter override that the node does not declare (a typo would otherwise be
        ignored silently), or a params file with no section for the node.
    """
    why = params_files.unmatched_files(params_files.GLOBAL_FILES, node.get_fully_qualified_name())
    if why:
        raise ConfigError(why)
    values: dict[str, Any] = {}
    overrides = getattr(node, "_parameter_overrides", None) or {}
    for p in params:
        _coerce_override(overrides, p)
        desc = ParameterDescriptor(name=p.name, type=p.type, description=p.description,
                                   read_only=p.read_only and not gated)
        try:
            if isinstance(p.default, tuple) and not p.default:
                # an empty default has no type of its own: declare by type, fall back below
                ptype = Parameter.Type(p.type)
                node.declare_parameter(p.name, ptype, desc)
            else:
                node.declare_parameter(p.name, list(p.default) if isinstance(p.default, tuple) else p.default,
                                       desc)
        except InvalidParameterTypeException:
            # rclpy's exception carries only a message: the offending value is the override's
            got = overrides.get(p.name)
            got_type = None if got is None else got.type_
            floats = (ParameterType.PARAMETER_DOUBLE, ParameterType.PARAMETER_DOUBLE_ARRAY)
            ints = (Parameter.Type.INTEGER, Parameter.Type.INTEGER_ARRAY)
            hint = ("; write floats with a decimal point, e.g. 2.0"
                    if p.type in floats and got_type in ints else "")
            got_s = "" if got is None else f" (got {got.value!r}, {got_type.name.lower()})"
            raise ConfigError(f"parameter '{p.name}' must be a {p.type_name}{got_s}{hint}") from None
        try:
            v = node.get_parameter(p.name).value
        except ParameterUninitializedException:
            v = p.default
        if v is None:
            v = p.default
        if isinstance(p.default, tuple):
            v = tuple(v)
        values[p.name] = v
    why = unknown_parameters(overrides, params, node.get_name())
    if why:
        raise ConfigError(why)
    return values


#: Parameters every rclpy node declares itself.
_RCLPY_OWN = ("use_sim_time", "start_type_description_service")


def unknown_parameters(names: Iterable[str], params: list[Param], node_name: str) -> str:
    """'' when every name in ``names`` is a declared parameter, else one line naming the unknown
    ones, the closest known name for each, and the known ones.

    One message for a misspelled parameter at start-up (a params file, ``-p``) and at run time
    (``ros2 param set``, the ``set_parameters`` services), where rclpy's own is
    ``Invalid access to undeclared parameter(s): []``.
    """
    known = sorted(p.name for p in params)
    declared = set(known) | set(_RCLPY_OWN)
    unknown = sorted({n for n in names if n not in declared and not n.startswith("qos_overrides.")})
    if not unknown:
        return ""
    hints = []
    by_lower = {k.lower(): k for k in known}
    for n in unknown:
        # a name that differs in case only (schedule.H) is that name; else the closest one, case ignored
        close = [by_lower[n.lower()]] if n.lower() in by_lower else \
            [by_lower[c] for c in difflib.get_close_matches(n.lower(), list(by_lower), n=1, cutoff=0.75)]
        if close:
            hints.append(f"'{n}': did you mean '{close[0]}'?")
    return (f"unknown parameter{'s' if len(unknown) > 1 else ''} {', '.join(unknown)} for node '{node_name}'"
            + (f" ({'; '.join(hints)})" if hints else "") + f" (known: {', '.join(known)})")
