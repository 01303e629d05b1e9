"""``mcap_records.message_records``: the Message records of an uncompressed MCAP chunk read straight from
its bytes are those ``mcap``'s own reader yields; lengths that do not add up are refused."""

from __future__ import annotations

import struct

import numpy as np
import pytest
from mcap.data_stream import ReadDataStream
from mcap.reader import breakup_chunk, make_reader
from mcap.records import Chunk, Message
from rclpy.serialization import serialize_message
from std_msgs.msg import Float64MultiArray

from switchobs_ros.bag.io import BagOut
from switchobs_ros.bag.mcap_records import message_records


def _bag(path, seed: int) -> bytes:
    rng = np.random.default_rng(seed)
    with BagOut(path, "mcap") as out:
        for t in ("/a", "/b", "/c"):
            out.add(t, "std_msgs/msg/Float64MultiArray")
        for k in range(300):
            data = serialize_message(Float64MultiArray(data=rng.standard_normal(int(rng.integers(0, 3000))).tolist()))
            out.write(("/a", "/b", "/c")[int(rng.integers(3))], 1000 + 7 * k - int(rng.integers(0, 50)), data)
    return next(path.glob("*.mcap"))


@pytest.mark.parametrize("seed", [0, 1])
def test_chunk_records_are_the_readers(tmp_path, seed):
    f = _bag(tmp_path / "b", seed)
    with f.open("rb") as fh:
        chunks = make_reader(fh).get_summary().chunk_indexes
        assert len(chunks) > 2
        for ci in chunks:
            fh.seek(ci.chunk_start_offset + 9)
            raw = fh.read(ci.chunk_length - 9)
            fh.seek(ci.chunk_start_offset + 9)
            want = [(r.channel_id, r.log_time, bytes(r.data)) for r in
                    breakup_chunk(Chunk.read(ReadDataStream(fh)), validate_crc=False) if isinstance(r, Message)]
            assert message_records(raw) == want and want
            with pytest.raises(ValueError):
                message_records(raw[:len(raw) // 2])        # records past the end
            bad = bytearray(raw)
            bad[41:49] = (2 ** 40).to_bytes(8, "little")     # the first record's length past the chunk's end
            with pytest.raises(ValueError):
                message_records(bytes(bad))


@pytest.mark.parametrize("extra", [0, 3])
def test_a_channel_metadata_does_not_list_is_skipped_in_log_order(tmp_path, extra):
    """An MCAP file with a channel that metadata.yaml does not list (with or without messages): the log
    order reads the listed topic's messages, as ``messages()`` does, instead of refusing the file."""
    import yaml
    from mcap.writer import CompressionType
    from mcap.writer import Writer as McapWriter

    from switchobs_ros.bag.io import BagIn

    bag = tmp_path / "b"
    bag.mkdir()
    data = [serialize_message(Float64MultiArray(data=[float(k)])) for k in range(50)]
    with (bag / "x.mcap").open("wb") as fh:
        w = McapWriter(fh, chunk_size=512, compression=CompressionType.NONE)
        w.start(profile="ros2", library="test")
        sid = w.register_schema("std_msgs/msg/Float64MultiArray", "ros2msg", b"float64[] data")
        listed, unlisted = w.register_channel("/a", "cdr", sid), w.register_channel("/extra", "cdr", sid)
        for k, d in enumerate(data):
            w.add_message(listed, log_time=1000 + k, data=d, publish_time=1000 + k, sequence=k)
        for j in range(extra):
            w.add_message(unlisted, log_time=1020 + j, data=data[0], publish_time=1020 + j, sequence=j)
        w.finish()
    topic = {"name": "/a", "type": "std_msgs/msg/Float64MultiArray", "serialization_format": "cdr",
             "offered_qos_profiles": "", "type_description_hash": ""}
    info = {"version": 8, "storage_identifier": "mcap", "relative_file_paths": ["x.mcap"],
            "duration": {"nanoseconds": 50}, "starting_time": {"nanoseconds_since_epoch": 1000},
            "message_count": 50, "topics_with_message_count": [{"topic_metadata": topic, "message_count": 50}],
            "compression_format": "", "compression_mode": "",
            "files": [{"path": "x.mcap", "starting_time": {"nanoseconds_since_epoch": 1000},
                       "duration": {"nanoseconds": 50}, "message_count": 50}],
            "custom_data": {}, "ros_distro": "jazzy"}
    (bag / "metadata.yaml").write_text(yaml.safe_dump({"rosbag2_bagfile_information": info}))
    b = BagIn(bag)
    ordered = list(b.log_order())
    assert [m.topic for m in ordered] == ["/a"] * 50
    assert [m.data for m in ordered] == [m.data for m in b.messages(order="log")] == data


@pytest.mark.parametrize("keep", [0, 5, 31, 39, 41, 50])
def test_a_cut_chunk_raises_value_error(keep):
    """Bytes cut inside the chunk's header, a record's header or its body: ``ValueError`` (what the
    reader turns into a clear refusal), never ``struct.error``."""
    record = struct.pack("<BQ", 5, 22 + 3) + struct.pack("<HIQQ", 1, 0, 7, 7) + b"abc"    # a Message record
    head = struct.pack("<QQQII", 7, 7, len(record), 0, 0)     # times, size, crc, compression "" (length 0)
    chunk = head + struct.pack("<Q", len(record)) + record
    assert message_records(chunk) == [(1, 7, b"abc")]
    with pytest.raises(ValueError):
        message_records(chunk[:keep])
