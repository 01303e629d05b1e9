"""The YAML of a bag's metadata written without ruamel's emitter (switchobs_ros.bag.metadata_yaml): byte for
byte ruamel's (``YAML(typ="safe")``, block style) for the documents rosbags writes, and None (ruamel's turn)
outside the subset it writes."""

from __future__ import annotations

from io import StringIO

from hypothesis import given, settings
from hypothesis import strategies as st
from ruamel.yaml import YAML

from switchobs_ros.bag import metadata_yaml
from switchobs_ros.bag.metadata_yaml import block_yaml


def _ruamel(data) -> str:
    y = YAML(typ="safe")
    y.default_flow_style = False
    s = StringIO()
    y.dump(data, s)
    return s.getvalue()


def _qos(depth: int, reliability: str) -> dict:
    zero = {"sec": 0, "nsec": 0}
    return {"history": "keep_last", "depth": depth, "reliability": reliability, "durability": "volatile",
            "deadline": zero, "lifespan": dict(zero), "liveliness": "system_default",
            "liveliness_lease_duration": {"sec": 2147483647, "nsec": 4294967295},
            "avoid_ros_namespace_conventions": False}


def _metadata(topics: list[str], path: str, custom) -> dict:
    return {"rosbag2_bagfile_information": {
        "version": 9, "storage_identifier": "mcap", "relative_file_paths": [path],
        "duration": {"nanoseconds": 20_000_000_000}, "starting_time": {"nanoseconds_since_epoch": 10 ** 9},
        "message_count": 43044,
        "topics_with_message_count": [
            {"topic_metadata": {"name": t, "type": "nav_msgs/msg/Odometry", "serialization_format": "cdr",
                                "offered_qos_profiles": [_qos(10 + i, "reliable" if i % 2 else "best_effort")],
                                "type_description_hash": "RIHS01_" + "3f" * 32},
             "message_count": 1001 + i} for i, t in enumerate(topics)],
        "compression_format": "", "compression_mode": "",
        "files": [{"path": path, "starting_time": {"nanoseconds_since_epoch": 10 ** 9},
                   "duration": {"nanoseconds": 20_000_000_000}, "message_count": 43044}],
        "custom_data": custom, "ros_distro": "rosbags"}}


def test_a_bag_metadata_and_its_qos_are_ruamels():
    """metadata.yaml of 45 topics (a type hash longer than its line: moved to the next) and one
    connection's QoS list: written here (not None), equal to ruamel's."""
    data = _metadata([f"/estimator/agent{i}/odom" for i in range(45)], "out.mcap", None)
    text = block_yaml(data)
    assert text is not None and text == _ruamel(data)
    assert "type_description_hash: \n        RIHS01_" in text
    qos = [_qos(10, "reliable"), _qos(1, "best_effort")]
    assert block_yaml(qos) == _ruamel(qos)


NAME = st.text(alphabet="abcXY_/.-09 :#'\"@", min_size=0, max_size=90)


@settings(max_examples=200, deadline=None)
@given(topics=st.lists(NAME, min_size=1, max_size=4), path=NAME,
       custom=st.one_of(st.none(), st.dictionaries(NAME, st.one_of(NAME, st.integers(), st.booleans()), max_size=3)))
def test_any_names_are_ruamels_or_left_to_it(topics, path, custom):
    """Property: topic names, a file name and custom data of any length (line wrapping at every
    indentation) and characters (quoting, reserved words): the text is ruamel's, or None."""
    data = _metadata(topics, path, custom)
    text = block_yaml(data)
    assert text is None or text == _ruamel(data)


@settings(max_examples=100, deadline=None)
@given(names=st.lists(st.from_regex(r"/[a-z][a-z0-9_/]{0,100}", fullmatch=True), min_size=1, max_size=3))
def test_topic_names_are_written_here(names):
    """Property: ROS topic names of every length up to the line's width and beyond are written here
    (not left to ruamel), as ruamel writes them."""
    data = _metadata(names, "b.mcap", None)
    text = block_yaml(data)
    assert text is not None and text == _ruamel(data)


def test_writer_yaml_is_ruamels_outside_the_subset():
    """The YAML rosbags' writer is given writes what ruamel writes, also for what block_yaml leaves to
    ruamel (a float, an empty mapping)."""
    metadata_yaml.install()
    from rosbags.rosbag2 import writer

    for data in ({"a": 1.5, "b": [{}]}, _metadata(["/a b"], "x.mcap", None), [_qos(3, "reliable")]):
        y = writer.YAML(typ="safe")
        y.default_flow_style = False
        s = StringIO()
        y.dump(data, s)
        assert s.getvalue() == _ruamel(data)
