"""A hook at the estimator's first input message (not a test; used by ``bench/profile_node.py`` and
``bench/phase_node.py``): what a live benchmark's CPU per answer counts starts at the first tick, not
at the node's construction (the wait for the sender, and the pairing timer's graph queries while the
channel's type is not settled, left out)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

__all__ = ["at_first_input"]

_INPUTS = ("on_input", "on_channel")


def at_first_input(pipeline: Any, start: Callable[[], None]) -> None:
    """Call ``start()`` once, at the first call of ``pipeline.on_input`` or ``pipeline.on_channel``
    (before it runs); the pipeline's own methods run unchanged, then and after."""
    def hooked(name: str):
        fn = getattr(pipeline, name)

        def first(*args, **kwargs):
            if "on_input" in vars(pipeline):
                for n in _INPUTS:
                    delattr(pipeline, n)
                start()
            return fn(*args, **kwargs)
        return first

    for name in _INPUTS:
        setattr(pipeline, name, hooked(name))
