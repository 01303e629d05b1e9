"""rclpy's log lines name their caller without a visit of every loaded module
(switchobs_ros.log_callers): the caller named is the one rclpy names without it."""

from __future__ import annotations

import inspect
import os
import sys
import types

import pytest
from rclpy.impl.rcutils_logger import CallerId

from switchobs_ros.log_callers import register_log_callers


class _Tripwire(types.ModuleType):
    """A module that fails when anything asks for its file: a visit of ``sys.modules``."""

    @property
    def __file__(self):
        raise AssertionError("inspect visited every loaded module")


def _log_site() -> tuple[CallerId, int]:
    """What rclpy's logger records for a log call on this line, and this line's number."""
    return CallerId(), inspect.currentframe().f_lineno


@pytest.fixture
def empty_cache(monkeypatch):
    """inspect's file-to-module cache empty, and a module in sys.modules that no visit survives."""
    monkeypatch.setattr(inspect, "modulesbyfile", {})
    monkeypatch.setattr(inspect, "_filesbymodname", {})
    monkeypatch.setitem(sys.modules, "switchobs_test_tripwire", _Tripwire("switchobs_test_tripwire"))


def test_an_unregistered_caller_visits_every_module(empty_cache):
    """The tripwire works: without registration rclpy's caller lookup visits sys.modules."""
    with pytest.raises(AssertionError, match="visited every loaded module"):
        _log_site()


def test_a_registered_caller_is_named_without_a_visit(empty_cache):
    register_log_callers(__name__)
    caller, line = _log_site()
    assert caller.function_name == "_log_site"
    assert caller.file_path == os.path.abspath(__file__)
    assert caller.line_number == line
    # the entries are the ones the visit writes: the module's file maps to its name
    assert inspect.getmodule(sys._getframe(), __file__) is sys.modules[__name__]


def test_registration_names_the_same_caller_as_rclpy_alone():
    plain, line = _log_site()
    register_log_callers(__name__, "no.such.module")       # a module not loaded is skipped
    seeded, _ = _log_site()
    assert (seeded.function_name, seeded.file_path, seeded.line_number) == \
        (plain.function_name, plain.file_path, plain.line_number) == ("_log_site", os.path.abspath(__file__), line)
