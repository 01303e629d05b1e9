"""A progress bar over the named steps of a long design (tqdm on stderr)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any


class StageBar:
    """``bar = StageBar(names, enabled)``; ``bar.next()`` at each step, ``bar.close()`` at the end.

    ``enabled``: True always, None on a terminal only, False never (tqdm is not imported then)."""

    def __init__(self, names: Sequence[str], enabled: bool | None) -> None:
        self.names = tuple(names)
        self.k = 0
        self._bar: Any = None
        if enabled is not False:
            from tqdm import tqdm

            self._bar = tqdm(total=len(self.names), disable=None if enabled is None else not enabled, leave=False,
                             unit="step", bar_format="{desc} [{n_fmt}/{total_fmt}] {elapsed}")
            self._bar.set_description_str(self.names[0])

    def next(self) -> None:
        """The current step is done; the next one starts."""
        self.k += 1
        if self._bar is not None:
            self._bar.update(1)
            if self.k < len(self.names):
                self._bar.set_description_str(self.names[self.k])

    def close(self) -> None:
        if self._bar is not None:
            self._bar.close()
