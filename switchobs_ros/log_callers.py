"""rclpy log lines without a visit of every loaded module.

rclpy names the caller of each log line (function, file, line): its ``CallerId`` calls
``inspect.getframeinfo`` on the logger's frames and the caller's, and ``inspect.getmodule`` maps
each frame's file to its module through a cache (``inspect.modulesbyfile``). A file not in that
cache makes it visit every module in ``sys.modules`` to fill it: about 900 modules in the
estimator, 25-50 ms at its first log line (``estimator ready`` or the one before it).

:func:`register_log_callers` enters the files of rclpy's logger and of the given modules in that
cache with the entries the visit itself would write (the absolute and the real path of each
module's source, mapped to the module's name), so the first line costs what every later one
does. The caller rclpy names is the same (``test_log_callers.py``); a log call from a module not
registered fills the cache by the visit, as rclpy alone does.
"""

from __future__ import annotations

import inspect
import os
import sys

__all__ = ["register_log_callers"]

#: rclpy's modules whose frames every log call walks through before it reaches its caller.
RCLPY_LOGGING = ("rclpy.impl.rcutils_logger", "rclpy.logging")


def register_log_callers(*modules: str) -> None:
    """Enter rclpy's logging modules and ``modules`` (names in ``sys.modules``) in ``inspect``'s
    file-to-module cache. A name not loaded, or a module without a source file, is skipped."""
    for name in (*RCLPY_LOGGING, *modules):
        module = sys.modules.get(name)
        if module is None or not isinstance(getattr(module, "__file__", None), str):
            continue
        try:
            f = inspect.getabsfile(module)
        except TypeError:           # a built-in module
            continue
        for key in (module.__file__, f, os.path.realpath(f)):
            inspect.modulesbyfile.setdefault(key, module.__name__)
