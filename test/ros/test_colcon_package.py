"""The documented colcon recipe (docs/how-to/ros2.md, "With ROS 2 from PyPI"), end to end in the
project's environment: its lines build both packages (switchobs_msgs and switchobs_ros) from a copy
of the repository in a temporary workspace; the packages are found through the ament index as
`ros2 run` finds them, the workspace's code and messages are what is imported, and
<prefix>/lib/switchobs_ros/estimator, started as the page's last line starts it, publishes."""

from __future__ import annotations

import os
import re
import shlex
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest

from tools.launch import NodeProcess

REPO = Path(__file__).resolve().parents[2]
PAGE = REPO / "docs" / "how-to" / "ros2.md"


def documented_recipe() -> tuple[list[str], str]:
    """The lines of the page's PyPI-environment block, and the colcon line of its ROS-installation
    block (the same command in both)."""
    from test_docs_code import blocks

    bash = [b for b in blocks() if b[0] == "docs/how-to/ros2.md" and b[2] == "bash" and "colcon build" in b[3]]
    assert len(bash) == 2, "the page documents the colcon build twice: on a ROS installation and with PyPI ROS"
    ros_install, pypi = (b[3].splitlines() for b in bash)
    colcon = [ln for ln in ros_install if ln.startswith("colcon build")]
    assert len(colcon) == 1
    return pypi, colcon[0]


def _copy_repository(dest: Path) -> None:
    """What `git clone` gives: the tracked files (and new, not ignored ones) of the work tree."""
    files = subprocess.run(["git", "ls-files", "-co", "--exclude-standard"], cwd=REPO, capture_output=True,
                           text=True, check=True).stdout.splitlines()
    for f in files:
        src = REPO / f
        if src.is_file():
            (dest / f).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(src, dest / f)


def _clean_env() -> dict[str, str]:
    """What `. .venv/bin/activate` does; a clean environment otherwise (no sourced ROS, no PYTHONPATH)."""
    env = {k: v for k, v in os.environ.items()
           if k not in ("AMENT_PREFIX_PATH", "COLCON_PREFIX_PATH", "CMAKE_PREFIX_PATH", "PYTHONPATH")}
    env.update(VIRTUAL_ENV=sys.prefix, PATH=f"{Path(sys.executable).parent}:{env.get('PATH', '')}")
    return env


def build_documented_workspace(ws: Path) -> None:
    """The page's build in ``ws``: a copy of the repository in ws/src/switchobs_ros (the clone), then
    its export line and its colcon line; the build's exit code and output go to ws/build.json.
    Done once per test run (``colcon_workspace`` in conftest.py): test_typed_msgs.py imports
    switchobs_msgs from the same workspace."""
    import json

    lines, colcon_line = documented_recipe()
    (ws / "src" / "switchobs_ros").mkdir(parents=True)
    _copy_repository(ws / "src" / "switchobs_ros")           # the clone
    script = "\n".join(["set -e", lines[1], f"cd {ws}", colcon_line + " --event-handlers console_direct-"])
    build = subprocess.run(["bash", "-c", script], capture_output=True, text=True, env=_clean_env(), timeout=900)
    (ws / "build.json").write_text(json.dumps({"returncode": build.returncode,
                                               "output": build.stdout[-3000:] + build.stderr[-3000:]}))


@pytest.mark.slow
def test_colcon_build_and_ament_index_run(colcon_workspace, tmp_path, paper_tables):
    lines, colcon_line = documented_recipe()
    assert lines[0] == ". .venv/bin/activate"
    assert lines[1] == 'export AMENT_PREFIX_PATH="$VIRTUAL_ENV" CMAKE_PREFIX_PATH="$VIRTUAL_ENV"'
    assert lines[2] == "mkdir -p ~/ws/src && cd ~/ws/src && git clone <this repository> switchobs_ros"
    assert lines[3] == f"cd ~/ws && {colcon_line}", "the same colcon build on a ROS installation and here"
    assert lines[4] == "source install/setup.bash"
    run = re.fullmatch(r'("\$\(python -c .*\)/lib/switchobs_ros/estimator") (--ros-args .*)', lines[5])
    assert run, lines[5]
    ws, build = colcon_workspace
    assert build["returncode"] == 0, build["output"]
    env = _clean_env()
    install = ws / "install"
    for pkg in ("switchobs_msgs", "switchobs_ros"):
        assert (install / pkg / "share" / "ament_index" / "resource_index" / "packages" / pkg).exists(), pkg
    lib = install / "switchobs_ros" / "lib" / "switchobs_ros"
    for exe in ("estimator", "managed_estimator", "camera_sim", "switchobs", "switchobs_bag"):
        assert (lib / exe).exists(), exe
    share = install / "switchobs_ros" / "share" / "switchobs_ros"
    for f in ("config/estimator.yaml", "config/robot_template.yaml", "config/switchobs.rviz",
              "launch/estimator.launch.py", "launch/estimator_camera_sim.launch.py"):
        assert (share / f).exists(), f

    # `source install/setup.bash`, then what `ros2 run switchobs_ros estimator` resolves: the page's own line
    probe = ("from ament_index_python.packages import get_package_prefix, get_package_share_directory;"
             "import switchobs_ros, switchobs_msgs.msg, os;"
             "print(get_package_share_directory('switchobs_ros'));"
             "print(os.path.dirname(switchobs_ros.__file__));"
             "print(os.path.dirname(switchobs_msgs.msg.__file__))")
    script = "\n".join(["set -e", lines[1], f"cd {ws}", lines[4], f"echo {run.group(1)}",
                         f'python -c "{probe}"', "env"])
    out = subprocess.run(["bash", "-c", script], capture_output=True, text=True, env=env, timeout=60)
    assert out.returncode == 0, out.stderr
    exe, share_dir, modpath, msgpath = out.stdout.splitlines()[:4]
    assert Path(exe) == lib / "estimator"
    assert Path(share_dir) == share
    assert Path(modpath).is_relative_to(install), "the colcon-installed code is what runs"
    assert Path(msgpath).is_relative_to(install / "switchobs_msgs"), "the workspace's messages are imported"
    sourced = dict(line.split("=", 1) for line in out.stdout.splitlines()[4:] if "=" in line)
    run_env = dict(env, AMENT_PREFIX_PATH=sourced["AMENT_PREFIX_PATH"], PYTHONPATH=sourced.get("PYTHONPATH", ""))
    args = [a.replace("install/", f"{install}/", 1) for a in shlex.split(run.group(2))]

    import rclpy
    from ros_harness import EstimatorIO, spin_until
    from std_msgs.msg import UInt8

    import msg_bridge as mb

    proc = NodeProcess("estimator", [*args, "-p", f"gain_table:={paper_tables['periodic']}"],
                       cmd=[exe], env=run_env, log=tmp_path / "estimator.log")
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
