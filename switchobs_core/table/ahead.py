"""A gain table file read in a worker thread while the caller builds the system it is checked against.

Reading a table (:func:`switchobs_core.table.io.load` without a system: the file read, its checksum,
the finiteness and layout checks, the :class:`~switchobs_core.table.gains.GainTable` built) needs
nothing of the system; checking it against the system (its fingerprint and observable bases, the
end of ``load`` with a system) does. The estimator's start builds the system (one observability
decomposition per channel: QR and eigh in LAPACK) and reads the table (``readinto``, SHA-256 and
``isfinite`` over the gains: all release the GIL), one after the other; :class:`TableReadAhead` runs
the read in a daemon thread started before the system is built, and :meth:`TableReadAhead.table`
joins it and makes the system check in the caller's thread. The table is the one
``load(path, system=system)`` gives, and so is any refusal: the same exception, raised by
:meth:`~TableReadAhead.table` in the caller's thread (``test_ahead.py``).
"""

from __future__ import annotations

import threading
from pathlib import Path
from typing import Any

from ..model.system import LTISystem
from . import io as table_io

__all__ = ["TableReadAhead"]


class TableReadAhead:
    """``cls.load(path)`` started now in a daemon thread; :meth:`table` takes its result once.

    A caller that will not take it calls :meth:`close` (the estimator's configuration does on a refused
    parameter); a thread left reading does not hold the process's exit (daemon).
    """

    def __init__(self, cls: Any, path: str | Path) -> None:
        self.cls = cls
        self.path = Path(path)
        self._result: Any = None
        self._error: Exception | None = None
        self._taken = False
        self._thread = threading.Thread(target=self._read, name="table-read-ahead", daemon=True)
        self._thread.start()

    def _read(self) -> None:
        try:
            self._result = table_io.load(self.cls, self.path)
        except Exception as err:        # raised again by table(), in the caller's thread
            self._error = err

    def close(self) -> None:
        """Wait for the read to end and drop what it gave (a caller that will not take the table)."""
        self._thread.join()
        self._taken = True
        self._result = self._error = None

    def table(self, system: LTISystem | None = None) -> Any:
        """The table, checked against ``system`` when given: what ``cls.load(path, system=system)``
        returns or raises. Taken once: a second call reads the file again, in the caller's thread."""
        if self._taken:
            return table_io.load(self.cls, self.path, system=system)
        self._thread.join()
        self._taken = True
        table, error = self._result, self._error
        self._result = self._error = None
        if error is not None:
            raise error
        if system is not None:
            table.check_system(system, source=str(self.path))
        return table
