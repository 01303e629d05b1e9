"""``mcap_records.message_records``: the Message records of an uncompressed MCAP chunk read straight from
its bytes are those ``mcap``'s own reader yields; lengths that do not add up are refused."""

from __future__ import annotations

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
