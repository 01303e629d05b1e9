"""The header stamp's rule in one owner (msg_bridge.stamps.time_ns): the per-message paths that
apply it, timed against a base tree side by side, interleaved rounds, medians.

    OPENBLAS_NUM_THREADS=1 .venv/bin/python bench/bench_stamp_owner.py /tmp/base-own11 [rounds]

Each round runs one child per tree (this tree first, then the base; the order alternates), and
each child times, best of 7 batches of 20000 calls: ``Source.checked`` of a serialised
PoseStamped (the live node's raw path, check_pose) and PointStamped (its own stamp check),
``FieldReader.read`` of an rclpy PoseStamped, and ``labelled_stamp_ns``.
"""

from __future__ import annotations

import json
import os
import statistics
import subprocess
import sys

_CHILD = r"""
import json, timeit
from rclpy.serialization import serialize_message
import msg_bridge as mb
from msg_bridge.convert import labelled_stamp_ns
from msg_bridge.frames import FramedFields
from switchobs_ros.sources import Source

def source(t, fields, pose):
    return Source(0, "/x", t, fields, None, ((0, 1),), False, mb.FieldReader(t, fields).read, pose,
                  FramedFields(t, fields), mb.Parser(t, fields))

def msg(t, fields):
    m = mb.message_class(t)()
    m.header.stamp.sec, m.header.stamp.nanosec, m.header.frame_id = 12, 345, "map"
    return m

out = {}
for name, t, fields, pose in (("checked PoseStamped", "geometry_msgs/msg/PoseStamped",
                               ("pose.position.x", "pose.position.y"), True),
                              ("checked PointStamped", "geometry_msgs/msg/PointStamped",
                               ("point.x", "point.y"), False)):
    src, data = source(t, fields, pose), serialize_message(msg(t, fields))
    kw = dict(frame_id="map", max_abs=1e6, last_ns=None, now_ns=10**12, future_tolerance_ns=500_000_000)
    assert src.checked(data, **kw)[2] is None
    out[name] = min(timeit.repeat(lambda: src.checked(data, **kw), number=20000, repeat=7)) / 20000
m = msg("geometry_msgs/msg/PoseStamped", None)
read = mb.FieldReader("geometry_msgs/msg/PoseStamped", ("pose.position.x", "pose.position.y")).read
out["FieldReader.read PoseStamped"] = min(timeit.repeat(lambda: read(m), number=20000, repeat=7)) / 20000
out["labelled_stamp_ns"] = min(timeit.repeat(lambda: labelled_stamp_ns(12.0, 345.0), number=20000, repeat=7)) / 20000
print(json.dumps(out))
"""


def _child(tree: str) -> dict[str, float]:
    env = dict(os.environ, PYTHONPATH=tree, OPENBLAS_NUM_THREADS="1")
    r = subprocess.run([sys.executable, "-c", _CHILD], env=env, cwd=tree, capture_output=True, text=True, check=True)
    return json.loads(r.stdout)


def main() -> None:
    base = sys.argv[1]
    rounds = int(sys.argv[2]) if len(sys.argv) > 2 else 9
    here = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    runs: dict[str, list[dict[str, float]]] = {"this": [], "base": []}
    for k in range(rounds):
        for which in (("this", "base") if k % 2 == 0 else ("base", "this")):
            runs[which].append(_child(here if which == "this" else base))
    print(f"{'path':32s} {'this us':>9s} {'base us':>9s} {'this/base':>9s}   ({rounds} rounds, medians)")
    for name in runs["this"][0]:
        t = statistics.median(r[name] for r in runs["this"]) * 1e6
        b = statistics.median(r[name] for r in runs["base"]) * 1e6
        print(f"{name:32s} {t:9.3f} {b:9.3f} {t / b:9.3f}")


if __name__ == "__main__":
    main()
