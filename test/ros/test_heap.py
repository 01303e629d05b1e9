"""switchobs_ros.heap: the estimators' console scripts keep glibc's heap between samples."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import types
from pathlib import Path

import pytest

from switchobs_ros import entry, heap

REPO = Path(__file__).resolve().parents[2]

GLIBC = (os.confstr("CS_GNU_LIBC_VERSION") or "").startswith("glibc") if "CS_GNU_LIBC_VERSION" in \
    os.confstr_names else False

# A sample's n x n temporaries at n = 132 (139 KB each), allocated together and freed together, as
# a Kalman correction and its outputs do; minor faults over the rounds after the first, before and
# after keep_heap, in a fresh interpreter (glibc's settings are the process's).
_CHURN = """
import json, resource, sys
import numpy as np
from switchobs_ros import heap

def faults(rounds=30):
    np.ones((132, 132)) * 2.0           # one mapped and freed: glibc raises its thresholds to it
    for k in range(rounds):
        if k == 1:
            f0 = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
        xs = [np.ones((132, 132)) for _ in range(4)]
        del xs
    return resource.getrusage(resource.RUSAGE_SELF).ru_minflt - f0

before = faults()
set_ = heap.keep_heap({})
print(json.dumps({"before": before, "after": faults(), "set": set_}))
"""


def test_the_environments_own_malloc_settings_are_left_alone():
    assert not heap.user_configured({})
    assert not heap.user_configured({"GLIBC_TUNABLES": "glibc.rtld.optional_static_tls=4096", "MALLOC_X": "1"})
    for env in ({"MALLOC_TRIM_THRESHOLD_": "0"}, {"MALLOC_MMAP_THRESHOLD_": "131072"},
                {"GLIBC_TUNABLES": "glibc.malloc.trim_threshold=1"},
                {"GLIBC_TUNABLES": "glibc.rtld.nns=2:glibc.malloc.hugetlb=1"}):
        assert heap.user_configured(env), env
        assert heap.keep_heap(env) is None, env


@pytest.mark.skipif(not GLIBC, reason="the setting is glibc's")
def test_kept_heap_faults_a_samples_temporaries_in_once():
    env = {k: v for k, v in os.environ.items() if not heap.user_configured({k: v})}
    out = subprocess.run([sys.executable, "-c", _CHURN], env=dict(env, PYTHONPATH=str(REPO)),
                         capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    r = json.loads(out.stdout.strip().splitlines()[-1])
    assert r["set"] == {"mmap_threshold": heap.MMAP_THRESHOLD, "trim_threshold": heap.TRIM_THRESHOLD}
    pages = 4 * 132 * 132 * 8 // 4096           # the four temporaries' pages
    # glibc's own thresholds: the temporaries are returned to the kernel and faulted in again, round
    # after round (29 rounds measured); kept, they are faulted in once (a few pages of slack).
    assert r["before"] >= 5 * pages
    assert r["after"] <= pages // 4


def test_the_estimators_console_scripts_keep_the_heap(monkeypatch):
    from switchobs_core import lean_scipy
    calls = []
    monkeypatch.setattr(heap, "keep_heap", lambda: calls.append(1))
    monkeypatch.setattr(lean_scipy, "import_scipy", lambda: None)
    monkeypatch.setattr(entry.importlib, "import_module", lambda name: types.SimpleNamespace(main=lambda: 0))
    assert entry.managed_estimator() == 0
    assert calls == [1]
    assert entry.camera_sim() == 0
    assert calls == [1]             # not the other nodes
