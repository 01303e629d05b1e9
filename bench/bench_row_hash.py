"""What verifying a Kalman table's row costs here: hashlib's digests of one 70 KB row (n = 132: 8778
float64 numbers) from bytes, a memoryview and an ndarray, hot (timeit, best of 5 per round), and a
first visit of rows of the table with the caches cold (8 MiB written before each): ``os.pread``,
then SHA-256 (bench/RESULTS.md, branch ``cold``).

    OPENBLAS_NUM_THREADS=1 python bench/bench_row_hash.py [--table /tmp/boot/k32v4.npz] [--rounds 15]
"""

from __future__ import annotations

import argparse
import hashlib
import os
import statistics
import sys
import time
import timeit
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--table", default="/tmp/boot/k32v4.npz")
    ap.add_argument("--rounds", type=int, default=15)
    a = ap.parse_args(argv)
    m = 132 * 133 // 2
    raw = np.random.default_rng(1).standard_normal(m).tobytes()
    mv, arr, head = memoryview(raw), np.frombuffer(raw, dtype="<f8"), f"P_prior[17] <f8 ({m},)\n".encode()

    def digest(algo, data):
        def run():
            h = hashlib.new(algo, head)
            h.update(data)
            return h.hexdigest()
        return run
    cases = {"sha256, bytes": digest("sha256", raw), "sha256, memoryview": digest("sha256", mv),
             "sha256, ndarray .data": digest("sha256", arr.data), "blake2b, bytes": digest("blake2b", raw),
             "sha1, bytes": digest("sha1", raw), "md5, bytes": digest("md5", raw),
             "np.isfinite(row).all()": lambda: bool(np.isfinite(arr).all())}
    got: dict[str, list[float]] = {k: [] for k in cases}
    for _ in range(a.rounds):        # interleaved rounds
        for k, f in cases.items():
            got[k].append(min(timeit.repeat(f, number=50, repeat=5)) / 50 * 1e6)
    print(f"Hot, one row of {8 * m} bytes, median of {a.rounds} rounds [min - max] (us), "
          f"load {os.getloadavg()[0]:.1f}:\n")
    print("| digest | us per row | GB/s |\n|---|---|---|")
    for k, v in got.items():
        med = statistics.median(v)
        print(f"| {k} | {med:.1f} [{min(v):.1f} - {max(v):.1f}] | {8 * m / med / 1e3:.2f} |")
    sys.path.insert(0, str(REPO))
    from switchobs_core.table.container import decode
    from switchobs_core.table.rows import LazyRows
    rows = next(v for v in _walk(decode(a.table)) if isinstance(v, LazyRows))
    junk = np.zeros(8 * 2**20, dtype=np.uint8)
    size, pr, sh, whole = 8 * rows.m, [], [], []
    for k in range(min(len(rows), 400)):
        junk[::64] += 1
        t0 = time.thread_time_ns()
        if k % 2:
            rows.row(k)
            whole.append((time.thread_time_ns() - t0) / 1e3)
            continue
        b = os.pread(rows._file.fd, size, rows._offset + k * size)
        t1 = time.thread_time_ns()
        h = hashlib.sha256(head)
        h.update(b)
        h.hexdigest()
        pr.append((t1 - t0) / 1e3)
        sh.append((time.thread_time_ns() - t1) / 1e3)
    print(f"\nFirst visits of {a.table}'s rows, caches cold (median, us): `os.pread` {statistics.median(pr):.1f}, "
          f"SHA-256 {statistics.median(sh):.1f}; `LazyRows.row` whole {statistics.median(whole):.1f}")
    return 0


def _walk(obj, depth=0):
    yield obj
    if depth < 6 and isinstance(obj, dict):
        for v in obj.values():
            yield from _walk(v, depth + 1)
    elif depth < 6 and isinstance(obj, (list, tuple)):
        for v in obj[:50]:
            yield from _walk(v, depth + 1)


if __name__ == "__main__":
    sys.exit(main())
