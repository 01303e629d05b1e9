"""Per-measurement cost of the estimator node in process, with jittered stamps (not a test).

``python bench/profile_node_step.py [--jitter-us 50] [--n 30000] [--cprofile K] [--domain D]``:
feeds camera/target pairs every 2 ms +- jitter straight into the node's callbacks' code (pipeline
+ publishing, no DDS receive; the pose messages are built outside the timed part), switching
channel every second, and prints the median (and its publishing part), p99 and maximum time per
measurement, the garbage collections seen after ``gc.freeze()`` and the exact-step cache's hits
and misses (bench/RESULTS.md, "Estimator node over DDS"). ``--cprofile K`` prints the K functions
with the most own time.
"""

from __future__ import annotations

import argparse
import gc
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--jitter-us", type=float, default=50.0)
    ap.add_argument("--n", type=int, default=30000)
    ap.add_argument("--domain", type=int, default=None, help="ROS_DOMAIN_ID to use (default: claim a free one)")
    ap.add_argument("--cprofile", type=int, default=0, metavar="K", help="print the K costliest functions (cProfile)")
    a = ap.parse_args()
    from tools.domain import claim_domain, localhost_env

    lease = claim_domain()
    import os
    os.environ.update(localhost_env(lease.domain_id if a.domain is None else a.domain))
    import rclpy
    from rclpy.parameter import Parameter
    from std_msgs.msg import UInt8

    import msg_bridge as mb
    from switchobs_core.design.lmi import design_table
    from switchobs_core.model.scenarios import load_system
    from switchobs_core.model.schedule import Cycle
    from switchobs_core.threads import single_threaded_blas
    from switchobs_ros.estimator import EstimatorNode

    single_threaded_blas()
    table = design_table(load_system("paper"), [Cycle.from_ts(2.0, 0.6)], progress=False)
    path = table.save(Path(tempfile.mkdtemp()) / "paper.json")
    rclpy.init()
    node = EstimatorNode(parameter_overrides=[Parameter("gain_table", value=str(path))])
    gc.freeze()
    pauses: list[float] = []
    start = [0.0]

    def on_gc(phase, info):
        if phase == "start":
            start[0] = time.perf_counter()
        else:
            pauses.append(time.perf_counter() - start[0])
    gc.callbacks.append(on_gc)
    pl = node.pipeline
    pl.on_channel(UInt8(data=1))
    rng = np.random.default_rng(0)
    j = int(a.jitter_us * 1000)
    stamps = time.time_ns() + np.cumsum(2_000_000 + (rng.integers(-j, j + 1, a.n) if j else np.zeros(a.n, int)))
    dur = np.zeros(a.n)
    pub = np.zeros(a.n)
    prof = None
    if a.cprofile:
        import cProfile
        prof = cProfile.Profile()
        prof.enable()
    for k in range(a.n):
        s = int(stamps[k])
        cam, tgt = mb.xy_to_pose((0.001 * k, 0.0), s, "map"), mb.xy_to_pose((3.0, 1.0), s, "map")   # the sensor's
        if k % 500 == 250:
            pl.on_channel(UInt8(data=2 if (k // 500) % 2 == 0 else 1))
        t = time.perf_counter()
        node._publish_all(pl.on_pose("camera", cam, s))
        est = pl.on_pose("target", tgt, s)
        t1 = time.perf_counter()
        node._publish_all(est)
        t2 = time.perf_counter()
        dur[k] = t2 - t
        pub[k] = t2 - t1
    if prof is not None:
        import pstats
        prof.disable()
        pstats.Stats(prof).sort_stats("tottime").print_stats(a.cprofile)
    c = pl.observer.cache
    print(f"jitter +-{a.jitter_us:g} us, {a.n} measurements: median {np.median(dur) * 1e6:.0f} us "
          f"(publishing {np.median(pub) * 1e6:.0f} us), "
          f"p99 {np.percentile(dur, 99) * 1e6:.0f} us, max {dur.max() * 1e3:.2f} ms; "
          f"garbage collections {len(pauses)} (max {max(pauses, default=0) * 1e3:.2f} ms); "
          f"exact-step cache hits {c.hits}, misses {c.misses}")
    node.destroy_node()
    rclpy.try_shutdown()
    lease.release()
    return 0


if __name__ == "__main__":
    sys.exit(main())
