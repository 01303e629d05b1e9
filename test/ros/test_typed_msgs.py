"""switchobs_msgs: the package built by the bootstrap is importable and in the ament index; the
writers and readers of msg_bridge.typed round-trip; StateEstimate, ErrorBounds and the markers
cross DDS between two processes; rosbags writes and reads both types in an mcap bag."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from rclpy.serialization import deserialize_message, serialize_message
from switchobs_msgs.msg import ErrorBounds, StateEstimate
from typed_talker import LABELS, NS, content

import msg_bridge as mb
from msg_bridge.typed import (
    MSG_TYPES,
    NO_BOUND_WHY,
    ErrorBoundsWriter,
    StateEstimateWriter,
    msg_dir,
    read_error_bounds,
    read_state_estimate,
    register_rosbags_types,
)

HERE = Path(__file__).resolve().parent
REPO = HERE.parents[1]

S = 1_700_000_000_123_456_789


# --- the package -----------------------------------------------------------------------------

def test_package_is_installed_in_the_environment_prefix_and_indexed():
    import switchobs_msgs

    prefix = Path(sys.prefix).resolve()
    assert Path(switchobs_msgs.__file__).resolve().is_relative_to(prefix), "installed into the venv prefix"
    # found through the ament index as the wheels' packages are (AMENT_PREFIX_PATH = the prefix)
    probe = ("from ament_index_python.packages import get_package_prefix, get_package_share_directory as s;"
             "print(get_package_prefix('switchobs_msgs')); print(get_package_prefix('std_msgs'));"
             "print(s('switchobs_msgs'))")
    env = dict(os.environ, AMENT_PREFIX_PATH=str(prefix))
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, env=env, timeout=60)
    assert out.returncode == 0, out.stderr
    mine, std, share = out.stdout.split()
    assert Path(mine).resolve() == Path(std).resolve() == prefix
    for name in ("StateEstimate", "ErrorBounds"):
        installed = (Path(share) / "msg" / f"{name}.msg").read_text()
        assert installed == (REPO / "interfaces" / "switchobs_msgs" / "msg" / f"{name}.msg").read_text(), \
            f"{name}.msg: the installed definition is the repository's (scripts/bootstrap.sh rebuilds on change)"
    assert msg_dir() == Path(share) / "msg"


@pytest.mark.slow
def test_colcon_builds_the_package_in_a_workspace(colcon_workspace):
    """What a ROS user does: the package in a workspace's src, `colcon build`, source, import. The
    workspace is the documented one (docs/how-to/ros2.md, built once per test run by the
    ``colcon_workspace`` fixture; test_colcon_package.py checks the rest of it): switchobs_msgs
    there comes from interfaces/switchobs_msgs of a copy of the repository."""
    ws, build = colcon_workspace
    assert build["returncode"] == 0, build["output"]
    assert (ws / "src" / "switchobs_ros" / "interfaces" / "switchobs_msgs" / "package.xml").read_text() \
        == (REPO / "interfaces" / "switchobs_msgs" / "package.xml").read_text()
    bindir = str(Path(sys.executable).parent)
    env = {k: v for k, v in os.environ.items() if k not in ("AMENT_PREFIX_PATH", "COLCON_PREFIX_PATH", "PYTHONPATH")}
    env.update(AMENT_PREFIX_PATH=sys.prefix, CMAKE_PREFIX_PATH=sys.prefix, PATH=f"{bindir}:{env.get('PATH', '')}")
    install = ws / "install"
    probe = ("from ament_index_python.packages import get_package_prefix;"
             "import switchobs_msgs.msg as m, os;"
             "print(get_package_prefix('switchobs_msgs')); print(os.path.dirname(m.__file__));"
             "print(sorted(m.StateEstimate.get_fields_and_field_types()))")
    out = subprocess.run(["bash", "-c", f"source {install}/setup.bash && python -c \"{probe}\""],
                         capture_output=True, text=True, env=env, timeout=60)
    assert out.returncode == 0, out.stderr
    prefix, modpath, fields = out.stdout.splitlines()
    assert Path(prefix) == install / "switchobs_msgs"
    assert Path(modpath).is_relative_to(install), "the workspace's build is what is imported"
    assert fields == str(sorted(["header", "labels", "x", "covariance"]))


def test_fields_are_the_documented_ones():
    assert StateEstimate.get_fields_and_field_types() == {
        "header": "std_msgs/Header", "labels": "sequence<string>", "x": "sequence<double>",
        "covariance": "sequence<double>"}
    assert ErrorBounds.get_fields_and_field_types() == {
        "header": "std_msgs/Header", "exact_bound": "double", "exact_bound_valid": "boolean",
        "noise_bound": "double", "noise_bound_declared": "boolean", "noise_bound_valid": "boolean",
        "paper_bound": "double", "paper_envelope": "sequence<double>", "why_invalid": "string"}
    # every field is documented: the group of field lines it belongs to follows a comment block
    for name, cls in (("StateEstimate", StateEstimate), ("ErrorBounds", ErrorBounds)):
        lines = (REPO / "interfaces" / "switchobs_msgs" / "msg" / f"{name}.msg").read_text().splitlines()
        for field in cls.get_fields_and_field_types():
            i = next(k for k, line in enumerate(lines) if not line.startswith("#") and line.split()[-1:] == [field])
            while i > 0 and lines[i - 1].strip() and not lines[i - 1].startswith("#"):
                i -= 1
            assert i > 0 and lines[i - 1].startswith("#"), f"{name}.{field} has no comment"


# --- writers and readers -----------------------------------------------------------------------

def test_state_estimate_roundtrip_with_and_without_covariance():
    w = StateEstimateWriter(LABELS, "map")
    x, P, _ = content(3)
    m = w.msg(x, S, P)
    r = read_state_estimate(deserialize_message(serialize_message(m), StateEstimate))
    assert (r.stamp_ns, r.frame_id, r.labels) == (S, "map", LABELS)
    np.testing.assert_array_equal(r.x, x)
    np.testing.assert_array_equal(r.P, P)
    assert list(m.covariance[:3]) == [P[0, 0], P[0, 1], P[0, 2]], "row-major"
    # the same message object, refilled; no covariance -> empty
    m2 = w.msg(x + 1, S + 1)
    assert m2 is m and len(m2.covariance) == 0
    r2 = read_state_estimate(m2)
    assert r2.P is None and r2.stamp_ns == S + 1
    np.testing.assert_array_equal(r2.x, x + 1)
    # a reading is a copy: refilling the writer does not change it
    w.msg(x * 0, S + 2, P)
    np.testing.assert_array_equal(r.x, x)


def test_state_estimate_reader_rejects_inconsistent_sizes():
    bad = StateEstimate(labels=["a", "b"], x=[1.0])
    with pytest.raises(ValueError, match="2 labels for 1 values"):
        read_state_estimate(bad)
    bad = StateEstimate(labels=["a", "b"], x=[1.0, 2.0], covariance=[1.0, 0.0, 0.0])
    with pytest.raises(mb.BridgeError, match="covariance has 3 values; expected 0 or 4"):
        read_state_estimate(bad)


def test_error_bounds_valid_withdrawn_and_not_available():
    w = ErrorBoundsWriter(2, "map", noise_declared=True)
    env = np.array([0.5, 0.25, 2.0, 0.1, 0.3])
    r = read_error_bounds(deserialize_message(serialize_message(w.msg(env, S, valid=True)), ErrorBounds))
    assert (r.stamp_ns, r.frame_id) == (S, "map")
    assert (r.exact_bound, r.exact_bound_valid, r.noise_bound, r.noise_bound_declared, r.noise_bound_valid) \
        == (0.1, True, 0.3, True, True)
    assert r.paper_bound == 2.0 and r.why_invalid == ""
    np.testing.assert_array_equal(r.paper_envelope, [0.5, 0.25])
    np.testing.assert_array_equal(r.envelope(), env)
    # withdrawn by the consistency test: the pipeline publishes -1, the reason travels along
    r = read_error_bounds(w.msg([0.5, 0.25, 2.0, -1.0, -1.0], S, valid=False, why="inconsistent sample"))
    assert not r.exact_bound_valid and not r.noise_bound_valid and r.why_invalid == "inconsistent sample"
    assert r.exact_bound == -1.0
    # a -1 bound (after a reset) is never valid, and says why even without a reason given
    r = read_error_bounds(w.msg([0.5, 0.25, -1.0, -1.0, 0.3], S, valid=True))
    assert not r.exact_bound_valid and r.noise_bound_valid and r.why_invalid == NO_BOUND_WHY
    assert r.paper_bound == -1.0


def test_error_bounds_without_declared_noise_and_wrong_layout():
    w = ErrorBoundsWriter(3, "odom", noise_declared=False)
    env = [1.0, 2.0, 3.0, 4.0, 0.5]
    assert mb.envelope_labels(3) == ("z_1", "z_2", "z_3", "paper_bound", "exact_bound")
    r = read_error_bounds(w.msg(env, 7, valid=True))
    assert (r.noise_bound_declared, r.noise_bound_valid, r.noise_bound) == (False, False, -1.0)
    assert r.exact_bound_valid and r.why_invalid == "" and r.frame_id == "odom"
    np.testing.assert_array_equal(r.envelope(), env)
    with pytest.raises(mb.BridgeError, match=r"envelope has 6 values; expected 5 \(z_1..z_3, paper_bound, exact"):
        w.msg(env + [1.0], 7, valid=True)


# --- DDS between two processes --------------------------------------------------------------------

def test_typed_messages_and_markers_cross_dds(ros_node, tmp_path):
    from ros_harness import spin_until
    from visualization_msgs.msg import MarkerArray

    from tools.launch import NodeProcess

    got: dict[str, list] = {"state_estimate": [], "error_bounds": [], "markers": []}
    for cls, name in ((StateEstimate, "state_estimate"), (ErrorBounds, "error_bounds"), (MarkerArray, "markers")):
        ros_node.create_subscription(cls, f"{NS}/{name}", got[name].append, 10)
    talker = NodeProcess("typed_talker", ["--seconds", "60"], cmd=[sys.executable, str(HERE / "typed_talker.py")],
                         log=tmp_path / "talker.log")
    try:
        ok = spin_until(ros_node, lambda: all(len(v) >= 3 for v in got.values()), 45.0)
        assert ok, {k: len(v) for k, v in got.items()} | {"log": talker.output()}
    finally:
        rc = talker.stop()
    assert rc == 0, talker.output()
    for m in got["state_estimate"]:
        r = read_state_estimate(m)
        k = r.stamp_ns // 1_000_000_000
        x, P, _ = content(k)
        assert r.labels == LABELS and r.frame_id == "map"
        np.testing.assert_array_equal(r.x, x)
        np.testing.assert_array_equal(r.P, P)
    for m in got["error_bounds"]:
        r = read_error_bounds(m)
        k = r.stamp_ns // 1_000_000_000
        np.testing.assert_array_equal(r.envelope(), content(k)[2])
        assert r.exact_bound_valid == r.noise_bound_valid == (k % 2 == 0)
        assert r.why_invalid == ("" if k % 2 == 0 else f"odd {k}")
    for m in got["markers"]:
        k = m.markers[0].header.stamp.sec
        x = content(k)[0]
        pos = {mk.id: mk for mk in m.markers if mk.ns == "switchobs/position"}
        assert [(p.pose.position.x, p.pose.position.y) for p in pos.values()] == [(x[0], x[1]), (x[4], x[5]),
                                                                                   (x[8], x[9])]


# --- rosbags (the bag tools' library): mcap -----------------------------------------------------

def test_rosbags_writes_and_reads_both_types_in_mcap(tmp_path):
    from mcap.reader import make_reader
    from rosbags.rosbag2 import Reader, StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_JAZZY)
    register_rosbags_types(store)
    register_rosbags_types(store)                      # again: harmless
    assert all(t in store.types for t in MSG_TYPES)

    x, P, env = content(5)
    msgs = {
        "/estimator/state_estimate": (MSG_TYPES[0], StateEstimateWriter(LABELS, "map").msg(x, S, P)),
        "/estimator/error_bounds": (MSG_TYPES[1],
                                    ErrorBoundsWriter(2, "map", True).msg(env, S, False, "withdrawn: test")),
    }
    bag = tmp_path / "typed_bag"
    with Writer(bag, version=9, storage_plugin=StoragePlugin.MCAP) as w:
        for topic, (typ, m) in msgs.items():
            conn = w.add_connection(topic, typ, typestore=store)
            w.write(conn, S, serialize_message(m))      # rclpy's CDR, as switchobs_bag writes it

    fresh = get_typestore(Stores.ROS2_JAZZY)           # a reader that registers the types itself
    register_rosbags_types(fresh)
    seen = {}
    with Reader(bag) as r:
        assert [c.msgtype for c in r.connections] == list(MSG_TYPES)
        for conn, t, raw in r.messages():
            seen[conn.topic] = (conn.msgtype, t, raw, fresh.deserialize_cdr(raw, conn.msgtype))
    assert set(seen) == set(msgs)

    typ, t, raw, st = seen["/estimator/state_estimate"]
    assert (typ, t) == (MSG_TYPES[0], S)
    assert tuple(st.labels) == LABELS and st.header.frame_id == "map"
    assert st.header.stamp.sec * 1_000_000_000 + st.header.stamp.nanosec == S
    np.testing.assert_array_equal(st.x, x)
    np.testing.assert_array_equal(np.asarray(st.covariance).reshape(12, 12), P)
    back = read_state_estimate(deserialize_message(raw, StateEstimate))   # and rclpy reads it back
    np.testing.assert_array_equal(back.P, P)

    typ, t, raw, eb = seen["/estimator/error_bounds"]
    assert typ == MSG_TYPES[1]
    assert (eb.exact_bound, eb.exact_bound_valid, eb.noise_bound, eb.noise_bound_declared, eb.noise_bound_valid) \
        == (env[3], False, env[4], True, False)
    assert eb.paper_bound == -1.0 and eb.why_invalid == "withdrawn: test"
    np.testing.assert_array_equal(eb.paper_envelope, env[:2])
    # rosbags' CDR reads back in rclpy as the message written (bytes may differ in padding only)
    assert deserialize_message(bytes(fresh.serialize_cdr(eb, MSG_TYPES[1])), ErrorBounds) \
        == deserialize_message(raw, ErrorBounds)

    # the mcap file carries the definitions (schemas), so other readers can decode it
    (mcap_file,) = bag.glob("*.mcap")
    with open(mcap_file, "rb") as f:
        schemas = {s.name: s.data.decode() for s in make_reader(f).get_summary().schemas.values()}
    assert "float64[] covariance" in schemas["switchobs_msgs/msg/StateEstimate"]
    assert "string why_invalid" in schemas["switchobs_msgs/msg/ErrorBounds"]


def test_register_rosbags_types_needs_the_installed_definitions(monkeypatch, tmp_path):
    import switchobs_msgs
    from rosbags.typesys import Stores, get_typestore

    fake = tmp_path / "lib" / "python3.11" / "site-packages" / "switchobs_msgs" / "__init__.py"
    fake.parent.mkdir(parents=True)
    fake.write_text("")
    monkeypatch.setattr(switchobs_msgs, "__file__", str(fake))
    with pytest.raises(mb.BridgeError, match="switchobs_msgs has no message definitions at .*rebuild it"):
        register_rosbags_types(get_typestore(Stores.ROS2_JAZZY))


def test_the_code_blocks_of_docs_typed_outputs_run():
    blocks = re.findall(r"```python\n(.*?)```", (REPO / "docs" / "typed-outputs.md").read_text(), re.S)
    assert len(blocks) == 3
    for code in blocks:
        exec(compile(code, "docs/typed-outputs.md", "exec"), {})


_BLOCK = """
import importlib.abc, sys
class _NoMsgs(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path, target=None):
        if name == "switchobs_msgs" or name.startswith("switchobs_msgs."):
            raise ModuleNotFoundError(f"No module named {name!r}", name=name)
sys.meta_path.insert(0, _NoMsgs())
sys.argv = [sys.argv[0], *sys.argv[1:]]
from switchobs_ros import entry
sys.exit(getattr(entry, sys.argv.pop(1))())
"""


@pytest.mark.parametrize("prog, args", [("estimator", []), ("managed_estimator", []),
                                        ("switchobs_bag", ["info", "nothing"])])
def test_without_the_message_package_one_line(prog, args):
    """A ``pip install`` without the interface package: the executables that publish or write the typed
    outputs say how to build it, one line and exit code 2 (no traceback); python -m switchobs_ros.bag too."""
    from switchobs_ros.entry import NO_MSGS

    r = subprocess.run([sys.executable, "-c", _BLOCK, prog, *args], capture_output=True, text=True, timeout=120)
    assert r.returncode == 2 and r.stderr == f"{prog}: error: {NO_MSGS}\n", r.stderr
    assert "scripts/build_msgs.sh" in NO_MSGS and "colcon" in NO_MSGS
