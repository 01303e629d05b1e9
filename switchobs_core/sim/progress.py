"""A progress bar over a simulation's samples (tqdm on stderr)."""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from typing import Any


def progress_bar(items: Iterable[Any], enabled: bool | None, unit: str) -> Iterator[Any]:
    """``items`` with a tqdm bar on stderr: ``enabled`` True always, None on a terminal only,
    False never (then the items themselves, without importing tqdm)."""
    if enabled is False:
        return iter(items)
    from tqdm import tqdm

    return iter(tqdm(items, disable=None if enabled is None else not enabled, leave=False, unit=unit))
