"""The estimator across emulated computers (network namespaces, test/ros/netns.py), side by side
in one run: a clean network, loss and jitter on the links, a fleet of two robots, and the channel
publisher's history depth under loss. Every published estimate is checked against the truth at its
stamp and the guaranteed bound published with it (test/ros/netns_collect.py). Needs root.

    ROS_DOMAIN_ID=104 python bench/bench_netns.py [--duration 15] [--only NAME ...]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT), str(ROOT / "test" / "ros")]

from bench_design import machine_info  # noqa: E402
from netns import Link, unavailable  # noqa: E402
from test_netns import PY, _run  # noqa: E402

#: camera_sim with its channel publisher's history forced to ``depth`` messages.
CAMERA_DEPTH = ("import sys; from rclpy.qos import QoSProfile, QoSReliabilityPolicy as R, QoSDurabilityPolicy as D; "
                "from switchobs_ros import qos; qos.channel_pub = lambda rate, w=0: QoSProfile(depth={depth}, "
                "reliability=R.RELIABLE, durability=D.TRANSIENT_LOCAL); from switchobs_ros.camera_sim import main; "
                "sys.argv = ['camera_sim', *sys.argv[1:]]; sys.exit(main())")


def conditions() -> dict[str, dict]:
    cam = {"camera": Link(0.0, 0.0, 0.10)}
    return {
        "clean, 3 computers": {},
        "2 % loss (camera link)": {"links": {"camera": Link(0.0, 0.0, 0.02)}},
        "20 +- 10 ms jitter (camera, detector links)": {"links": {"camera": Link(20.0, 10.0, 0.0),
                                                                  "detector": Link(20.0, 10.0, 0.0)}},
        "20 +- 10 ms jitter (camera, detector links), 2 % loss (camera link)": {
            "links": {"camera": Link(20.0, 10.0, 0.02), "detector": Link(20.0, 10.0, 0.0)}},
        "20 +- 10 ms jitter (camera, detector links), 10 % loss (camera link)": {
            "links": {"camera": Link(20.0, 10.0, 0.10), "detector": Link(20.0, 10.0, 0.0)}},
        "fleet /robot1 /robot2, clean": {"robots": ["robot1", "robot2"], "detector": ()},
        **{f"10 % loss (camera link), channel history {d}": {"links": cam, "camera_sim": (PY, "-c",
                                                                                         CAMERA_DEPTH.format(depth=d))}
           for d in (1, 5, 100)},
    }


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--duration", type=float, default=15.0)
    ap.add_argument("--only", nargs="*", default=None)
    a = ap.parse_args()
    why = unavailable()
    if why:
        print(f"bench_netns: skipped: {why}")
        return 0
    import os

    from switchobs_core.design.lmi import design_table
    from switchobs_core.model.scenarios import load_system
    from switchobs_core.model.schedule import Cycle

    domain = int(os.environ.get("ROS_DOMAIN_ID", "104"))
    tmp = Path(tempfile.mkdtemp(prefix="bench_netns_"))
    table = str(design_table(load_system("paper"), [Cycle.from_ts(2.0, 0.6)], delta=0.99).save(tmp / "t.json"))
    print(f"{machine_info()}; {a.duration:g} s per run at 100 Hz, shipped config/*.yaml\n")
    print("| condition | robot | estimates / truth | checked | above the bound | max err/bound | valid after 5 s "
          "| answered after 5 s | final error | lost / late channel msgs | partial updates | not proven in the window: "
          "target dropped / named | re-certified | bounds at the end |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for name, kw in conditions().items():
        if a.only and not any(o in name for o in a.only):
            continue
        d = tmp / name.replace(" ", "_").replace("/", "").replace("%", "pc")
        d.mkdir()
        robots = kw.pop("robots", ["robot1"])
        try:
            res = _run(d, domain, table, robots, duration=a.duration, **kw)
        except AssertionError as err:
            print(f"| {name} | - | failed: {str(err).splitlines()[0]} |")
            continue
        for ns, s in res.items():
            g = s["diagnostics"]
            print(f"| {name} | {ns} | {s['estimates']} / {s['truth']} | {s['checked']} | {s.get('above')} | "
                  f"{s.get('max_ratio') or float('nan'):.3g} | {100 * s.get('valid_after_5s', 0):.0f} % | "
                  f"{100 * s.get('answered_after_5s', 0):.0f} % | {s.get('final_error', float('nan')):.3g} | "
                  f"{g.get('lost channel messages', '?')} / {g.get('late channel messages', '?')} | "
                  f"{g.get('partial updates', '?')} | "
                  f"{g.get('samples not proven within the reorder window (channel rows dropped)', '-')} / "
                  f"{g.get('samples not proven within the reorder window, named by the consistency test', '-')} | "
                  f"{g.get('re-certifications from data', '?')} | {g.get('exact bound valid', '?')[:60]} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
