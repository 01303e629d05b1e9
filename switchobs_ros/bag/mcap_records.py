"""Message records of an MCAP bag written with fewer copies: the same bytes as rosbags' writer.

rosbags' ``McapWriter.write`` builds each Message record in a fresh ``BytesIO`` (the message's bytes
copied into it, then copied again into the chunk) with one small ``write`` per header field: at 32
agents, where ``switchobs_bag estimate`` writes 40 messages a tick, about a tenth of the command's
time. :func:`fast_records` gives a writer's storage a ``write`` that packs the record's 31-byte
header with one ``struct`` call and appends the message's bytes to the chunk once, and a
``close_chunk`` that writes the chunk and its message indexes (a chunk of about six ticks holds some
40 channels' indexes) with one ``struct`` call per record instead of one small ``write`` per field:
the chunk, its index and the file are byte for byte those of rosbags' own methods (tested); ``write_many`` appends
several messages of one log time (a tick's odometries) with one write, which
still write the summary and ``metadata.yaml``.

Only an uncompressed MCAP storage of the rosbags version whose record layout this reproduces
(checked on a sample record when the bag is opened) is given the fast path; anything else keeps
rosbags' method.
"""

from __future__ import annotations

import struct
from collections import defaultdict
from collections.abc import Sequence
from io import BytesIO
from itertools import chain
from types import MethodType
from typing import Any

__all__ = ["fast_records", "message_records"]

#: op (Message, 0x05), record length, channel id, sequence (0), log time, publish time (= log time).
_MESSAGE = struct.Struct("<BQHIQQ")
_OP_MESSAGE = 0x05
#: rosbags closes a chunk once it holds more than this many bytes.
_CHUNK_BYTES = 2 ** 20
#: op (Chunk, 0x06), record length, start, end, uncompressed size, CRC (0), compression "" (its length 0), size.
_CHUNK = struct.Struct("<BQQQQIIQ")
#: op (Message Index, 0x07), record length, channel id, the length of the (time, offset) pairs that follow.
_INDEX = struct.Struct("<BQHI")


def _write(self: Any, connection: Any, timestamp: int, data: bytes | memoryview) -> None:
    """``McapWriter.write`` (rosbags) with the record header packed at once."""
    if timestamp < self.message_start_time:
        self.message_start_time = timestamp
    if timestamp > self.message_end_time:
        self.message_end_time = timestamp
    cid = connection.id
    self.channel_stats[cid] += 1
    chunk = self.chunk
    if timestamp < chunk.message_start_time:
        chunk.message_start_time = timestamp
    if timestamp > chunk.message_end_time:
        chunk.message_end_time = timestamp
    bio = chunk.bio
    chunk.msgs[cid].append((timestamp, bio.tell()))
    size = data.nbytes if isinstance(data, memoryview) else len(data)
    bio.write(_MESSAGE.pack(_OP_MESSAGE, 22 + size, cid, 0, timestamp, timestamp))
    bio.write(data)
    if bio.tell() > _CHUNK_BYTES:
        self.close_chunk()


def _write_many(self: Any, connections: Sequence[Any], timestamp: int, datas: Sequence[Any]) -> None:
    """:func:`_write` for each ``(connection, data)`` in turn at one ``timestamp``, the records of a chunk
    appended with one ``writelines`` (each piece copied once; the chunk closed after the record that takes
    it past its size, as there). A ``data`` is bytes, a byte view, or a tuple of them: a message's bytes
    in pieces (:meth:`switchobs_ros.bag.cdr.Template.pieces`), written in turn without being joined."""
    if timestamp < self.message_start_time:
        self.message_start_time = timestamp
    if timestamp > self.message_end_time:
        self.message_end_time = timestamp
    stats = self.channel_stats
    chunk = self.chunk
    bio = chunk.bio
    pos = bio.tell()
    parts: list = []
    if connections:         # one log time: the chunk's span once (a chunk closed below starts anew)
        if timestamp < chunk.message_start_time:
            chunk.message_start_time = timestamp
        if timestamp > chunk.message_end_time:
            chunk.message_end_time = timestamp
    index = chunk.msgs
    fresh = False           # a chunk closed below: its first record sets its span
    for connection, data in zip(connections, datas):
        cid = connection.id
        stats[cid] += 1
        if fresh:
            if timestamp < chunk.message_start_time:
                chunk.message_start_time = timestamp
            if timestamp > chunk.message_end_time:
                chunk.message_end_time = timestamp
            fresh = False
        index[cid].append((timestamp, pos))
        if data.__class__ is tuple:
            size = sum(d.nbytes if isinstance(d, memoryview) else len(d) for d in data)
            parts.append(_MESSAGE.pack(_OP_MESSAGE, 22 + size, cid, 0, timestamp, timestamp))
            parts += data
        else:
            size = data.nbytes if isinstance(data, memoryview) else len(data)
            parts.append(_MESSAGE.pack(_OP_MESSAGE, 22 + size, cid, 0, timestamp, timestamp))
            parts.append(data)
        pos += _MESSAGE.size + size
        if pos > _CHUNK_BYTES:
            bio.writelines(parts)
            parts = []
            self.close_chunk()
            chunk = self.chunk
            bio = chunk.bio
            index = chunk.msgs
            pos = bio.tell()
            fresh = True
    if parts:
        bio.writelines(parts)


def _close_chunk(self: Any) -> None:
    """``McapWriter.close_chunk`` (rosbags, no compression) with a record per ``struct`` call."""
    chunk = self.chunk
    data = chunk.bio.getbuffer()
    size = data.nbytes
    bio = self.bio
    chunk_start = bio.tell()
    bio.write(_CHUNK.pack(0x06, 8 + 8 + 8 + 4 + 4 + 8 + size, chunk.message_start_time, chunk.message_end_time,
                          size, 0, 0, size))
    bio.write(data)
    del data
    chunk_end = pos = chunk_start + _CHUNK.size + size
    offsets = []
    index = []          # the message indexes, written at once
    for cid, msgs in chunk.msgs.items():
        offsets.append((cid, pos))
        k = len(msgs)
        index.append(_INDEX.pack(0x07, 6 + 16 * k, cid, 16 * k))
        index.append(struct.pack(f"<{2 * k}Q", *chain.from_iterable(msgs)))
        pos += _INDEX.size + 16 * k
    bio.write(b"".join(index))
    rec = BytesIO()
    rec.write(struct.pack("<QQQQI", chunk.message_start_time, chunk.message_end_time, chunk_start,
                          chunk_end - chunk_start, len(offsets) * 10))
    rec.write(struct.pack("<" + "HQ" * len(offsets), *chain.from_iterable(offsets)))
    rec.write(struct.pack("<QIQQ", pos - chunk_end, 0, size, size))
    self.chunks.append(rec)
    self.chunk = type(chunk)(2 ** 63 - 1, 0, BytesIO(), defaultdict(list))


#: A Chunk record's fields after its op and length: start, end, uncompressed size, CRC, the compression's length.
_CHUNK_HEAD = struct.Struct("<QQQII")
#: A record's op and length; a Message record's channel id, sequence, log time, publish time.
_RECORD = struct.Struct("<BQ")
_MESSAGE_HEAD = struct.Struct("<HIQQ")


def message_records(chunk: bytes) -> list[tuple[int, int, bytes]]:
    """``(channel id, log time, data)`` of each Message record in an uncompressed Chunk record's bytes
    (``chunk``: from the start time to the end of the records, the op and length left out), in the
    file's order; other records skipped. What ``mcap``'s ``breakup_chunk`` yields as Message records
    (without the CRC checked, as it is read here). Raises ``ValueError`` where the lengths do not add up."""
    if len(chunk) < _CHUNK_HEAD.size + 8:
        raise ValueError("a chunk shorter than its header")
    _, _, _, _, clen = _CHUNK_HEAD.unpack_from(chunk, 0)
    if clen:
        raise ValueError("a compressed chunk")
    at = _CHUNK_HEAD.size
    (size,) = struct.unpack_from("<Q", chunk, at)
    at += 8
    end = at + size
    if end > len(chunk):
        raise ValueError("the chunk's records run past its end")
    out = []
    unpack, head, msg = _RECORD.unpack_from, _RECORD.size, _MESSAGE_HEAD.unpack_from
    while at < end:
        if at + head > end:
            raise ValueError("a record header runs past the chunk's end")
        op, length = unpack(chunk, at)
        at += head
        if at + length > end:
            raise ValueError("a record runs past the chunk's end")
        if op == _OP_MESSAGE:
            if length < 22:
                raise ValueError("a Message record shorter than its header")
            cid, _, log_time, _ = msg(chunk, at)
            out.append((cid, log_time, chunk[at + 22:at + length]))
        at += length
    return out


def _same_layout(storage: Any) -> bool:
    """Whether rosbags' own ``write`` lays a sample record out as :func:`_write` does."""
    from rosbags.rosbag2 import storage_mcap

    probe = BytesIO()
    rec = BytesIO()
    try:
        storage_mcap.write_uint16(rec, 7)
        storage_mcap.write_uint32(rec, 0)
        storage_mcap.write_uint64(rec, 123456789)
        storage_mcap.write_uint64(rec, 123456789)
        rec.write(b"abc")
        storage_mcap.write_record(probe, _OP_MESSAGE, rec)
    except Exception:       # pragma: no cover - another rosbags: keep its method
        return False
    return (probe.getvalue() == _MESSAGE.pack(_OP_MESSAGE, 25, 7, 0, 123456789, 123456789) + b"abc"
            and getattr(storage, "compression", None) == "")


def fast_records(writer: Any) -> bool:
    """Give ``writer``'s storage (a rosbags ``Writer``, open) the fast Message record when it is an
    uncompressed MCAP storage laid out as :func:`_write` writes; True if it was given."""
    from rosbags.rosbag2.storage_mcap import McapWriter

    storage = getattr(writer, "storage", None)
    if type(storage) is not McapWriter or not _same_layout(storage):
        return False
    storage.write = MethodType(_write, storage)
    storage.close_chunk = MethodType(_close_chunk, storage)
    storage.write_many = MethodType(_write_many, storage)
    return True
