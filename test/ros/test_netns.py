"""The estimator across real network interfaces: camera_sim, a target detector and the estimator
on separate emulated computers (network namespaces on one switch, :mod:`netns`), discovery by
multicast on that switch (``ROS_AUTOMATIC_DISCOVERY_RANGE=SUBNET``), Fast DDS over UDPv4, and the
shipped config/estimator.yaml and config/camera_sim.yaml. Every published estimate is checked
against the truth camera_sim publishes at its stamp, and the guaranteed bound published with it.

The target detector is a republisher on a computer of its own: camera_sim's target poses (remapped
to ``detector/raw``) go from the camera's computer to the detector's, which publishes them on
``target/pose`` with their stamps, as a detector on another computer would. The computers share
one clock here (namespaces do not separate clocks), so these tests do not exercise clock offsets.

Skipped with the reason where network namespaces cannot be created (not root, no ``ip``).
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

import pytest
from netns import Link, Network, unavailable

REPO = Path(__file__).resolve().parents[2]
PY = sys.executable
WHY = unavailable()
pytestmark = pytest.mark.skipif(bool(WHY), reason=WHY or "network namespaces available")

#: Simulated (= wall) seconds of each run.
DURATION = 7.0

DETECTOR = """
import sys, rclpy
from geometry_msgs.msg import PoseStamped
from switchobs_ros import qos
rclpy.init()
node = rclpy.create_node("detector", namespace=sys.argv[1])
pub = node.create_publisher(PoseStamped, "target/pose", qos.SENSOR)
node.create_subscription(PoseStamped, "detector/raw", pub.publish, qos.SENSOR_SUB)
try:
    rclpy.spin(node)
except BaseException:
    pass
"""


def _run(tmp_path: Path, domain: int, table: str, robots: list[str], links: dict | None = None,
         detector: tuple[str, ...] = ("robot1",), duration: float = DURATION,
         camera_sim: tuple = (PY, "-m", "switchobs_ros.camera_sim"), estimator: tuple = ()) -> dict:
    """camera_sim per robot on "camera" (``camera_sim``: its command), a detector on "detector" for
    each robot of ``detector`` (the others' target poses come from camera_sim directly), an estimator
    per robot on "estimator" (``estimator``: extra ROS arguments), the collector on "observer"; the
    collector's summary per robot (also used by bench/bench_netns.py)."""
    hosts = ["camera", "detector", "estimator", "observer"] if set(detector) & set(robots) else \
        ["camera", "estimator", "observer"]
    out = tmp_path / "summary.json"
    with Network(hosts, links) as net:
        col = net.popen("observer", [PY, "test/ros/netns_collect.py", str(out), "--robots", *robots,
                                     "--timeout", str(duration + 30)], domain, tmp_path / "collector.log")
        for r in robots:
            ns = ["-r", f"__ns:=/{r}"]
            net.popen("estimator", [PY, "-m", "switchobs_ros.estimator", "--ros-args", "--params-file",
                                    "config/estimator.yaml", "-p", f"gain_table:={table}", *ns, *estimator], domain,
                      tmp_path / f"estimator-{r}.log")
            if r in detector:
                net.popen("detector", [PY, "-c", DETECTOR, f"/{r}"], domain, tmp_path / f"detector-{r}.log")
            cam = ["-r", "target/pose:=detector/raw"] if r in detector else []
            net.popen("camera", [*camera_sim, "--ros-args", "--params-file",
                                 "config/camera_sim.yaml", "-p", f"duration:={duration}", "-p",
                                 "wait_for_subscribers:=1", "-p", "wait_for_truth_subscribers:=1", *ns, *cam],
                      domain, tmp_path / f"camera_sim-{r}.log")
        end = time.monotonic() + duration + 40
        while col.poll() is None and time.monotonic() < end:
            time.sleep(0.2)
    logs = "\n".join(f"--- {p.name}\n{p.read_text()[-1500:]}" for p in sorted(tmp_path.glob("*.log")))
    assert out.exists(), f"the collector wrote nothing:\n{logs}"
    res = json.loads(out.read_text())
    for r in robots:
        assert res[f"/{r}"]["checked"] > 0, f"no estimate arrived for /{r}:\n{logs}"
    return res


def _no_false_bound(s: dict) -> None:
    assert s["above"] == 0, s
    assert s["bound_label"] == "noise_bound", s         # the shipped config declares noise.max (0: noise-free)


def test_three_computers_and_a_fleet_on_a_clean_network(tmp_path, ros_domain, paper_tables):
    """/robot1: camera, detector and estimator on three computers; /robot2 beside it (camera_sim's
    own target poses); both estimators with the shipped files (keyed /**) on one computer. Every
    published estimate within its published bound, answers after the first 5 s, and both estimators
    took the file's values (e0 5, the code's default is 1)."""
    res = _run(tmp_path, ros_domain, paper_tables["periodic"], ["robot1", "robot2"])
    for ns, s in res.items():
        _no_false_bound(s)
        assert float(s["diagnostics"]["e0"]) == 5.0, (ns, s)
        # answers: 99-100 % after 5 s in bench/bench_netns.py; a machine shared with other work loses
        # reliable channel messages to the load itself (26 of 700 once here, their target poses dropped)
        assert s["answered_after_5s"] >= 0.6 and s["valid"] > 0, (ns, s)


def test_jitter_and_loss_on_the_links(tmp_path, ros_domain, paper_tables):
    """20 +- 10 ms of delay on the camera's and the detector's links and 2 % loss on the camera's
    (the switch is the user-space relay): no published estimate above its bound."""
    links = {"camera": Link(20.0, 10.0, 0.02), "detector": Link(20.0, 10.0, 0.0)}
    (s,) = _run(tmp_path, ros_domain, paper_tables["periodic"], ["robot1"], links).values()
    _no_false_bound(s)
    assert s["checked"] > 0.5 * s["truth"], s
    # A valid bound on >= 90 % of the samples after the first 5 s: attribution by sensor stamps (the
    # stamped channel message camera_sim publishes) never compares the detector's clock with the camera's,
    # and a sample whose channel the stamps do not prove within the window is never guessed (its target
    # pose dropped), so a switching message lost or late on the lossy link cannot void an answer
    assert s["valid_after_5s"] >= 0.9, s
