"""Shared by the benchmarks that time the observer's step in child processes of several checkouts:
the ``camera_agents(M)`` model (every velocity mode 0.05/s) with an LMI table for its one-second
periodic cycle, and one timed child run."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path


def agents_lmi_table(M: int, prefix: str) -> tuple[Path, Path]:
    """``(system file, LMI table file)`` of ``camera_agents(M)`` for ``Cycle([1.0] * M)``, in a new
    temporary folder named with ``prefix``."""
    from switchobs_core.design.lmi import design_table
    from switchobs_core.model.scenarios import load_system
    from switchobs_core.model.schedule import Cycle

    work = Path(tempfile.mkdtemp(prefix=prefix))
    sysf = work / "system.yaml"
    sysf.write_text(f"scenario: camera_agents\nagents: {M}\nD_agents: {[[0.0, 0.05]] * M}\n")
    table = design_table(load_system(str(sysf)), [Cycle([1.0] * M)], progress=False).save(work / "gains.json")
    return sysf, Path(table)


def run_child(code: str, tree: Path, *args: object) -> dict:
    """Run ``code`` (``python -c``) on the checkout ``tree`` with one BLAS thread; its last stdout
    line, a JSON object."""
    env = dict(os.environ, PYTHONPATH=str(tree), OPENBLAS_NUM_THREADS="1", PYTHONSAFEPATH="1")
    out = subprocess.run([sys.executable, "-c", code, *map(str, args)], env=env, capture_output=True, text=True,
                         check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])
