"""One BLAS thread (switchobs_core.threads): set before the libraries load, or through threadpoolctl after."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]

_CHILD = """
import json, sys
from switchobs_core import threads
before = threads.single_thread_before_load()
import numpy, scipy.linalg
from threadpoolctl import threadpool_info
counts = sorted({i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"})
again = threads.single_thread_before_load()
print(json.dumps({"before": before, "counts": counts, "again": again, "limited": threads.single_threaded_blas(),
                  "libraries": len([i for i in threadpool_info() if i["user_api"] == "blas"])}))
"""


@pytest.mark.skipif(len(os.sched_getaffinity(0)) < 2, reason="OpenBLAS caps its threads at the CPUs: one CPU gives "
                    "one thread without the call, so the test could not fail")
def test_blas_threads_set_before_numpy_loads_them():
    """A process that asks before numpy and scipy are imported gets one thread in every BLAS they load,
    though its environment asked for 4; once numpy is imported the call changes nothing and says so,
    and single_threaded_blas has nothing left to do (one fresh interpreter)."""
    env = dict(os.environ, PYTHONPATH=str(REPO), OPENBLAS_NUM_THREADS="4", MKL_NUM_THREADS="4",
               BLIS_NUM_THREADS="4")
    out = subprocess.run([sys.executable, "-c", _CHILD], env=env, capture_output=True, text=True, timeout=120,
                         check=True)
    got = json.loads(out.stdout.strip().splitlines()[-1])
    assert got["before"] is True and got["again"] is False and got["limited"] is True
    assert got["libraries"] >= 1 and got["counts"] == [1]
