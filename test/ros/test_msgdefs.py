"""The message definitions an output bag declares without rosbags' type store (``switchobs_ros.bag.msgdefs``):
the kept ones are the type store's, and a bag written with them is byte for byte one written from the store."""

from __future__ import annotations

from importlib.metadata import version

import pytest
from rclpy.serialization import serialize_message
from std_msgs.msg import Float64MultiArray

from switchobs_ros.bag import io as bag_io
from switchobs_ros.bag import msgdefs, msgdefs_data
from switchobs_ros.bag.io import BagError, BagOut
from switchobs_ros.bag.msgdefs_data import DEFINITIONS, ROSBAGS, SWITCHOBS_MSGS


def test_the_kept_definitions_are_the_type_stores():
    """Every kept ``(msgdef, rihs01)`` is what rosbags' Jazzy store makes (switchobs_msgs registered), for the
    installed rosbags (else ``python -m switchobs_ros.bag.msgdefs`` writes them again); all of TYPES are kept."""
    assert ROSBAGS == version("rosbags") and SWITCHOBS_MSGS == msgdefs.msgs_digest()
    assert set(DEFINITIONS) == set(msgdefs.TYPES)
    assert msgdefs.generated() == DEFINITIONS
    assert msgdefs.definition("std_msgs/msg/UInt8") == DEFINITIONS["std_msgs/msg/UInt8"]
    assert msgdefs.definition("sensor_msgs/msg/Imu") is None


def _unasked(monkeypatch) -> None:
    """``definition`` asks the installed packages again (and forgets the answers after the test)."""
    monkeypatch.setattr(msgdefs, "_valid", {False: None, True: None})


def test_another_rosbags_asks_the_type_store(monkeypatch):
    _unasked(monkeypatch)
    monkeypatch.setattr(msgdefs_data, "ROSBAGS", "0.0.0")
    assert msgdefs.definition("std_msgs/msg/UInt8") is None
    assert msgdefs.definition("switchobs_msgs/msg/ErrorBounds") is None


def test_no_rosbags_installed_asks_the_type_store(monkeypatch):
    import importlib.metadata

    def missing(name):
        raise importlib.metadata.PackageNotFoundError(name)
    _unasked(monkeypatch)
    monkeypatch.setattr(importlib.metadata, "version", missing)
    assert msgdefs.definition("std_msgs/msg/UInt8") is None


def test_a_changed_switchobs_msgs_is_asked_of_the_type_store(monkeypatch, tmp_path):
    """A field added to an installed switchobs_msgs ``.msg`` (a changed, rebuilt package): its types are not
    handed out from the kept ones (the type store's differ: the bag declares the new definition and hash), the
    other kept types still are; ``write_data`` records the new digest, and with it they are kept again."""
    import shutil

    import msg_bridge.typed as typed

    changed = tmp_path / "msg"
    shutil.copytree(typed.msg_dir(), changed)
    (changed / "ErrorBounds.msg").write_text((changed / "ErrorBounds.msg").read_text() + "\nfloat64 extra_bound\n")
    monkeypatch.setattr(typed, "msg_dir", lambda: changed)
    _unasked(monkeypatch)
    t = "switchobs_msgs/msg/ErrorBounds"
    store = msgdefs.generated((t,))[t]
    assert store != DEFINITIONS[t]
    assert msgdefs.definition(t) is None
    assert msgdefs.definition("switchobs_msgs/msg/StateEstimate") is None
    assert msgdefs.definition("std_msgs/msg/UInt8") == DEFINITIONS["std_msgs/msg/UInt8"]
    data = tmp_path / "data.py"
    msgdefs.write_data(data)
    written: dict = {}
    exec(data.read_text(), written)
    assert written["SWITCHOBS_MSGS"] == msgdefs.msgs_digest() != SWITCHOBS_MSGS
    assert written["DEFINITIONS"][t] == store
    _unasked(monkeypatch)
    monkeypatch.setattr(msgdefs_data, "SWITCHOBS_MSGS", written["SWITCHOBS_MSGS"])
    monkeypatch.setattr(msgdefs_data, "DEFINITIONS", written["DEFINITIONS"])
    assert msgdefs.definition(t) == store


@pytest.mark.parametrize("storage", ["mcap", "sqlite3"])
def test_a_bag_from_kept_definitions_is_the_type_stores_bag(tmp_path, monkeypatch, storage):
    """The same connections and messages written with the kept definitions and with the type store's (one type
    not kept among them) give the same file and metadata.yaml; a type the store does not know is refused."""
    data = serialize_message(Float64MultiArray(data=[1.0, 2.0]))

    def write(path):
        with BagOut(path, storage) as out:
            for k, t in enumerate(msgdefs.TYPES):
                out.add(f"/t{k}", t)
            out.add("/imu", "sensor_msgs/msg/Imu")
            out.add("/a", "std_msgs/msg/Float64MultiArray")
            for k in range(5):
                out.write("/a", 1000 + k, data)
            kept = out._typestore is None
        return kept

    assert not write(tmp_path / "kept" / "b")          # the type store made for the Imu only
    monkeypatch.setattr(bag_io, "definition", lambda t: None)
    write(tmp_path / "store" / "b")
    for name in ("metadata.yaml", "b.mcap" if storage == "mcap" else "b.db3"):
        assert (tmp_path / "kept" / "b" / name).read_bytes() == (tmp_path / "store" / "b" / name).read_bytes()
    with BagOut(tmp_path / "x", storage) as out, pytest.raises(BagError, match="not in the ROS 2 Jazzy type store"):
        out.add("/z", "nope_msgs/msg/Nothing")
