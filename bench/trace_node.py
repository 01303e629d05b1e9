"""The estimator node as ``switchobs_ros.runner`` runs it, with a trace of where each answer's time
went (not a test; started by ``bench/bench_node.py --configs traced``).

``python bench/trace_node.py OUT.npz --ros-args ...``: spins the node with rclpy's
SingleThreadedExecutor after ``gc.freeze()``, as the runner does, and records

* ``inp``: per camera pose handled, its stamp, the wall time (``time.time_ns``) its handling
  began (so ``inp - stamp`` is the time from the sender to the node's callback: DDS and the
  node's queue) and the CPU time of the node's thread then (``time.thread_time_ns``: across a
  stall, whether the thread ran or was blocked or descheduled);
* ``pub``: per estimate published, its stamp and the wall time just after ``~/state`` went out;
* ``gc``: start and end (wall ns) of every garbage collection;

and saves them at exit (SIGINT). :func:`split` tells, for the answers later than a threshold,
where the time went: before the node took the measurement, inside the node, or after it
published (delivery to the receiver).
"""

from __future__ import annotations

import gc
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


def main(out: str, args: list[str]) -> None:
    import rclpy
    from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor

    import msg_bridge as mb
    from switchobs_core.threads import single_threaded_blas
    from switchobs_ros.estimator import EstimatorNode

    single_threaded_blas()
    rclpy.init(args=args)
    node = EstimatorNode()
    inp: list[tuple[int, int, int]] = []
    pub: list[tuple[int, int]] = []
    gcs: list[list[int]] = []
    publish_all = node._publish_all
    # the camera/pose input: its subscription and its handler (msg, MessageInfo)
    sub_cam, on_camera = next((s, h) for s, h in node._hot_inputs if s.topic_name.endswith("camera/pose"))

    def traced_camera(msg, info):
        inp.append((mb.stamp_to_ns(msg.header.stamp), time.time_ns(), time.thread_time_ns()))
        on_camera(msg, info)

    def traced_publish(estimates):
        publish_all(estimates)
        now = time.time_ns()
        pub.extend((e.stamp_ns, now) for e in estimates)

    def on_gc(phase, info):
        if phase == "start":
            gcs.append([time.time_ns(), 0])
        elif gcs:
            gcs[-1][1] = time.time_ns()

    sub_cam.callback = node._with_drain(traced_camera)
    node._publish_all = traced_publish
    node._hot_inputs = tuple((s, traced_camera if s is sub_cam else h) for s, h in node._hot_inputs)
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    gc.freeze()
    gc.callbacks.append(on_gc)
    try:
        executor.spin()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        np.savez(out, **{k: np.array(v, dtype=np.int64).reshape(-1, w)
                         for k, v, w in (("inp", inp, 3), ("pub", pub, 2), ("gc", gcs, 2))})
        node.destroy_node()
        rclpy.try_shutdown()


def split(trace: Path, sent: np.ndarray, arrival: dict, late_ms: float) -> str:
    """Where the answers later than ``late_ms`` (and the lost ones) spent their time."""
    t = np.load(trace)
    inp = dict(zip(t["inp"][:, 0].tolist(), t["inp"][:, 1].tolist()))
    pub = dict(zip(t["pub"][:, 0].tolist(), t["pub"][:, 1].tolist()))
    before = inside = after = lost_in = lost_after = 0
    for s in sent.tolist():
        if s not in arrival:
            if s in pub:
                lost_after += 1
            else:
                lost_in += 1
            continue
        if (arrival[s] - s) * 1e-6 <= late_ms:
            continue
        a, p = inp.get(s), pub.get(s)
        d_before = (a - s) * 1e-6 if a is not None else np.nan
        d_inside = (p - a) * 1e-6 if a is not None and p is not None else np.nan
        d_after = (arrival[s] - p) * 1e-6 if p is not None else np.nan
        k = int(np.nanargmax([d_before, d_inside, d_after])) if np.isfinite([d_before, d_inside, d_after]).any() else 0
        before += k == 0
        inside += k == 1
        after += k == 2
    g = t["gc"]
    gmax = float((g[:, 1] - g[:, 0]).max()) * 1e-6 if len(g) else 0.0
    gap = ""
    i = t["inp"]
    if len(i) > 1:
        k = int(np.argmax(np.diff(i[:, 1])))
        gap = (f"; longest gap between camera poses handled {(i[k + 1, 1] - i[k, 1]) * 1e-6:.1f} ms, "
               f"the node thread's CPU in it {(i[k + 1, 2] - i[k, 2]) * 1e-6:.1f} ms")
    return (f"late answers mostly before the node {before}, inside it {inside}, after it {after}; "
            f"lost before publishing {lost_in}, after {lost_after}; {len(g)} garbage collections "
            f"(max {gmax:.2f} ms){gap}")


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2:])
