"""What every thread of the benchmark's processes did while answers were late (not a test).

``python bench/perf_offcpu.py RUN.data RUN.npz [LATE_MS]`` reads a run kept by
``bench/bench_node.py --perf DIR`` (``perf record -a -e sched:sched_switch``, the machine's context
switches, and the run's stamps and arrival times) and prints, for the worst cluster of answers later
than ``LATE_MS`` (default 5) or lost:

* the busiest threads of the machine in that window (CPU time from the switches in and out);
* per process (node, sender, receiver): each thread's CPU time in the window and its longest
  off-CPU interval overlapping it, with the state it left the CPU in (``S`` sleeping, ``R``
  preempted, ``D`` waiting for I/O) and, if the record has call graphs (``-g``), where.

So a stall can be placed: a node thread asleep in its wait set while the witness got the data in
time points at the node's middleware; a sender that did not run points upstream; a machine whose
cores were taken by other threads points at scheduling.
"""

from __future__ import annotations

import re
import subprocess
import sys
from dataclasses import dataclass

import numpy as np

_HEAD = re.compile(r"^\s*(.*?)\s+(\d+)/(\d+)\s+([\d.]+):\s+prev_comm=(.*?) prev_pid=(\d+) .*?prev_state=(\S+) "
                   r"==> next_comm=(.*?) next_pid=(\d+)")


@dataclass
class Switch:
    t: float            # CLOCK_MONOTONIC seconds
    pid: int            # process of the thread leaving the CPU
    prev: int           # thread leaving the CPU
    prev_comm: str
    state: str          # the state it leaves in
    nxt: int            # thread taking the CPU
    stack: list[str]


def switches(data: str) -> list[Switch]:
    """The context switches of a ``perf record`` file (``perf script``)."""
    txt = subprocess.run(["perf", "script", "-i", data, "-F", "comm,pid,tid,time,trace,ip,sym,dso"],
                         capture_output=True, text=True, check=True).stdout
    out = []
    for block in txt.split("\n\n"):
        lines = block.strip("\n").split("\n")
        m = _HEAD.match(lines[0]) if lines and lines[0] else None
        if m:
            out.append(Switch(float(m[4]), int(m[2]), int(m[6]), m[5], m[7], int(m[9]),
                              [ln.strip() for ln in lines[1:]]))
    return out


def worst_window(run: np.lib.npyio.NpzFile, late_ms: float) -> tuple[float, float, int, int]:
    """``(start, end, n_bad, n_lost)`` of the worst cluster of late or lost answers, in the
    CLOCK_MONOTONIC seconds of the perf record."""
    sent, rec, off = run["sent"], run["rec"], int(run["realtime_minus_monotonic_ns"])
    arrival = dict(zip(rec[:, 0].tolist(), rec[:, 1].tolist()))
    lat = np.array([(arrival[s] - s) * 1e-6 if s in arrival else np.inf for s in sent.tolist()])
    bad = np.flatnonzero(lat > late_ms)
    if not bad.size:
        raise SystemExit(f"no answer later than {late_ms:g} ms in this run")
    k = int(np.argmax(np.where(np.isinf(lat), 1e9, lat)))
    cluster = bad[np.abs(bad - k) < 400]
    return ((sent[cluster.min()] - off) * 1e-9, (sent[cluster.max()] - off) * 1e-9 + 0.005, len(cluster),
            int(np.isinf(lat[cluster]).sum()))


def main(argv: list[str]) -> None:
    data, npz = argv[0], argv[1]
    late_ms = float(argv[2]) if len(argv) > 2 else 5.0
    run = np.load(npz)
    lo, hi, n_bad, n_lost = worst_window(run, late_ms)
    print(f"worst cluster: {n_bad} late or lost ({n_lost} lost), window {lo:.3f}..{hi:.3f} s "
          f"({(hi - lo) * 1e3:.0f} ms)")
    ev = switches(data)
    owner = {s.prev: (s.pid, s.prev_comm) for s in ev}
    on_since: dict[int, float] = {}
    off_since: dict[int, tuple[float, str, list[str]]] = {}
    oncpu: dict[int, float] = {}
    offs = []
    for s in ev:
        if s.prev in on_since:
            a, b = max(on_since.pop(s.prev), lo), min(s.t, hi)
            if b > a:
                oncpu[s.prev] = oncpu.get(s.prev, 0.0) + b - a
        off_since[s.prev] = (s.t, s.state, s.stack)
        on_since[s.nxt] = s.t
        if s.nxt in off_since:
            t0, state, stack = off_since.pop(s.nxt)
            if s.t > lo and t0 < hi:
                offs.append((min(s.t, hi) - max(t0, lo), t0, s.t, s.nxt, state, stack))
    print("busiest threads of the machine in the window: " + ", ".join(
        f"{owner.get(t, (0, '?'))[1]} (pid {owner.get(t, (0, '?'))[0]}) {v * 1e3:.1f} ms"
        for t, v in sorted(oncpu.items(), key=lambda kv: -kv[1])[:8] if t))
    roles = {int(run["node_pid"]): "node", int(run["sender_pid"]): "sender"}
    if "receiver_pid" in run.files:
        roles[int(run["receiver_pid"])] = "receiver"
    for pid, role in roles.items():
        tids = [t for t, (p, _) in owner.items() if p == pid]
        print(f"\n{role} (pid {pid}), CPU in the window: "
              + (", ".join(f"{owner[t][1]} {oncpu[t] * 1e3:.1f} ms" for t in tids if oncpu.get(t)) or "none"))
        for d, t0, t1, tid, state, stack in sorted((o for o in offs if o[3] in tids), reverse=True)[:4]:
            where = [x for x in stack if "kernel" not in x][:3] or [x.split()[1] for x in stack][2:5]
            print(f"   {owner[tid][1]}: off the CPU {d * 1e3:.1f} ms of the window ({t0:.3f} -> {t1:.3f}, "
                  f"left in state {state}) {where}")


if __name__ == "__main__":
    main(sys.argv[1:])
