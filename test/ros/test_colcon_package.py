"""The colcon route: colcon (PyPI) builds the package into a temporary workspace, the package is
found through the ament index as `ros2 run` finds it, and <prefix>/lib/switchobs_ros/estimator
starts and publishes."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest

from tools.launch import NodeProcess

REPO = Path(__file__).resolve().parents[2]
PARTS = ["package.xml", "setup.py", "setup.cfg", "resource", "config", "switchobs_core", "msg_bridge",
         "switchobs_ros"]


@pytest.mark.slow
def test_colcon_build_and_ament_index_run(tmp_path, paper_tables):
    colcon = shutil.which("colcon") or str(Path(sys.executable).parent / "colcon")
    assert Path(colcon).exists(), "colcon is installed from requirements.txt"
    src = tmp_path / "ws" / "src" / "switchobs_ros"
    src.mkdir(parents=True)
    for p in PARTS:
        s = REPO / p
        if s.is_dir():
            shutil.copytree(s, src / p, ignore=shutil.ignore_patterns("__pycache__", "*.pyc"))
        else:
            shutil.copy2(s, src / p)
    ws = tmp_path / "ws"
    build = subprocess.run([colcon, "build", "--base-paths", "src", "--event-handlers", "console_direct-"],
                           cwd=ws, capture_output=True, text=True, timeout=300)
    assert build.returncode == 0, build.stdout[-3000:] + build.stderr[-3000:]
    install = ws / "install"
    assert (install / "switchobs_ros" / "lib" / "switchobs_ros" / "estimator").exists()
    for exe in ("camera_sim", "switchobs", "switchobs_bag"):
        assert (install / "switchobs_ros" / "lib" / "switchobs_ros" / exe).exists(), exe
    assert (install / "switchobs_ros" / "share" / "switchobs_ros" / "config" / "estimator.yaml").exists()
    assert (install / "switchobs_ros" / "share" / "switchobs_ros" / "config" / "switchobs.rviz").exists()

    # what `ros2 run switchobs_ros estimator` does, after `source install/setup.bash`
    probe = ("from ament_index_python.packages import get_package_prefix, get_package_share_directory;"
             "import switchobs_ros, os;"
             "print(get_package_prefix('switchobs_ros'));"
             "print(get_package_share_directory('switchobs_ros'));"
             "print(os.path.dirname(switchobs_ros.__file__))")
    env = {k: v for k, v in os.environ.items() if k not in ("AMENT_PREFIX_PATH", "COLCON_PREFIX_PATH")}
    env["PATH"] = f"{Path(sys.executable).parent}:{env.get('PATH', '')}"
    out = subprocess.run(["bash", "-c", f"source {install}/setup.bash && python -c \"{probe}\" && env"],
                         cwd=tmp_path, capture_output=True, text=True, env=env, timeout=60)
    assert out.returncode == 0, out.stderr
    prefix, share, modpath = out.stdout.splitlines()[:3]
    assert Path(prefix) == install / "switchobs_ros"
    assert Path(share) == install / "switchobs_ros" / "share" / "switchobs_ros"
    assert Path(modpath).is_relative_to(install), "the colcon-installed code is what runs"
    sourced = dict(line.split("=", 1) for line in out.stdout.splitlines()[3:] if "=" in line)
    exe = Path(prefix) / "lib" / "switchobs_ros" / "estimator"
    run_env = dict(env, AMENT_PREFIX_PATH=sourced["AMENT_PREFIX_PATH"], PYTHONPATH=sourced.get("PYTHONPATH", ""))

    import rclpy
    from ros_harness import EstimatorIO, spin_until
    from std_msgs.msg import UInt8

    import msg_bridge as mb

    proc = NodeProcess("estimator", ["--ros-args", "--params-file", str(Path(share) / "config" / "estimator.yaml"),
                                     "-p", f"gain_table:={paper_tables['periodic']}"],
                       cmd=[str(exe)], env=run_env, log=tmp_path / "estimator.log")
    rclpy.init()
    node = rclpy.create_node("colcon_probe")
    try:
        io = EstimatorIO(node)
        assert io.wait_matched(30.0), proc.output()
        # A publisher can see its subscriber before the subscriber has matched it: send the channel
        # and a pair again (new stamps) until the first answer arrives.
        sent = []
        end = time.monotonic() + 20.0
        while not io.msgs["state"] and time.monotonic() < end:
            io.pub_channel.publish(UInt8(data=1))
            spin_until(node, lambda: False, 0.05)
            s = time.time_ns()
            io.pub_camera.publish(mb.xy_to_pose((0.0, 0.0), s, "map"))
            io.pub_target.publish(mb.xy_to_pose((3.0, 1.0), s, "map"))
            sent.append(s)
            spin_until(node, lambda: len(io.msgs["state"]) >= 1, 0.5)
        assert io.msgs["state"], proc.output()
        assert mb.unpack_labelled(io.msgs["state"][0]).stamp_ns in sent
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
        rc = proc.stop()
    assert rc == 0, proc.output()
