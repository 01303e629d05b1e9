"""Reading and writing rosbag2 bags: the container from ``rosbags``, the bytes from rclpy.

A bag here is a real rosbag2 bag (a folder with ``metadata.yaml``, version 9, and one ``.mcap``
or ``.db3`` file) as ``ros2 bag record`` writes it. Messages are CDR bytes, serialised and
deserialised with ``rclpy.serialization`` (the same bytes rosbags' own CDR serialiser
produces), so the player publishes exactly the recorded bytes and the offline estimator
deserialises exactly what the node would receive. Topic names in bags are absolute
(``/camera/pose``), as rosbag2 records them.

Message order: :meth:`BagIn.messages` returns the messages sorted by their log time (the
receive time on the recorder's clock), ties in the order of the file (the recorder's: the order
it received them), never by topic. The player publishes in this order; the offline estimator
checks it against the messages' own stamps first (:mod:`switchobs_ros.bag.order`).

Every failure is a :class:`BagError` with one line naming the file or the topic. Before anything
is opened, ``metadata.yaml`` (at most 1 MiB) and the data files (at most 1 GiB: most offline tools
hold the messages in memory; ``switchobs_bag estimate`` reads them as it goes, :meth:`BagIn.log_order`)
must be regular files (:mod:`switchobs_core.files`).
"""

from __future__ import annotations

import importlib
from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path

from switchobs_core.exceptions import SwitchobsError, one_line
from switchobs_core.files import MAX_BAG_BYTES, MAX_METADATA_BYTES, check_input
from switchobs_core.loading import load_yaml

from .. import qos
from .cdr import decode_uint8
from .mcap_records import fast_records, message_records
from .metadata_yaml import install as fast_yaml
from .msgdefs import definition, from_store, typestore

__all__ = [
    "CHANNEL_TYPES",
    "CONTRACT_TYPES",
    "channel_message",
    "STORAGES",
    "TOPIC_RANK",
    "BagError",
    "BagIn",
    "BagMessage",
    "BagOut",
    "msg_class",
    "qos_for",
    "type_name",
]

#: Storage plugins, by the name rosbag2 uses (``--storage``).
STORAGES = ("mcap", "sqlite3")

#: Types of the topics of the node contract (README, "Topics"), absolute names.
CONTRACT_TYPES = {
    "/camera/pose": "geometry_msgs/msg/PoseStamped",
    "/target/pose": "geometry_msgs/msg/PoseStamped",
    "/camera/active_channel": "switchobs_msgs/msg/ActiveChannel",
    "/sim/truth": "std_msgs/msg/Float64MultiArray",
    "/clock": "rosgraph_msgs/msg/Clock",
    "/diagnostics": "diagnostic_msgs/msg/DiagnosticArray",
}

#: The channel topic's types: stamped (the switching instant in the header) or the channel alone.
CHANNEL_TYPES = ("switchobs_msgs/msg/ActiveChannel", "std_msgs/msg/UInt8")

#: The topics of a paper-interface tick in camera_sim's publishing order (other topics rank 9): the
#: player's channel topic is rank 1. Ties of log time are never broken by it (module docstring).
TOPIC_RANK = {"/clock": 0, "/camera/active_channel": 1, "/camera/pose": 2, "/target/pose": 3, "/sim/truth": 4}


class BagError(SwitchobsError, ValueError):
    """A bag that cannot be used: missing, unreadable, truncated, a missing topic or a wrong type."""


def msg_class(type_name_: str) -> type:
    """The rclpy message class of ``pkg/msg/Name``."""
    try:
        pkg, kind, name = type_name_.split("/")
        return getattr(importlib.import_module(f"{pkg}.{kind}"), name)
    except (ValueError, ImportError, AttributeError):
        raise BagError(f"message type '{type_name_}' is not available here (no Python module {type_name_})") from None


def type_name(cls: type) -> str:
    """``pkg/msg/Name`` of an rclpy message class."""
    pkg = cls.__module__.split(".")[0]
    return f"{pkg}/msg/{cls.__name__}"


# --------------------------------------------------------------------------------- QoS
def _qos_kinds():
    return {"sensor": qos.SENSOR, "channel": qos.CHANNEL_PUB, "truth": qos.TRUTH, "clock": qos.CLOCK,
            "output": qos.OUTPUT}


def qos_kind(topic: str) -> str:
    """The QoS the node contract gives a topic (README, "Topics"), as a kind name."""
    if topic in ("/camera/pose", "/target/pose"):
        return "sensor"
    if topic == "/camera/active_channel":
        return "channel"
    if topic == "/sim/truth":
        return "truth"
    if topic == "/clock":
        return "clock"
    return "output"


def qos_for(topic: str):
    """The rclpy QoSProfile a publisher of ``topic`` uses under the node contract.

    Sensor poses: sensor data (best effort); the active channel: reliable, transient local,
    depth 1 (as camera_sim); ``/clock``: best effort; ``/sim/truth``: reliable, depth 100;
    everything else (the estimator's outputs, ``/diagnostics``): reliable, depth 10.
    """
    return _qos_kinds()[qos_kind(topic)]


def _rosbags_qos(profile):
    """rosbags' Qos of an rclpy QoSProfile (for ``offered_qos_profiles`` in metadata.yaml)."""
    from rosbags.interfaces import (
        Qos,
        QosDurability,
        QosHistory,
        QosLiveliness,
        QosReliability,
        QosTime,
    )
    zero = QosTime(0, 0)
    return Qos(history=QosHistory(int(profile.history)), depth=int(profile.depth),
               reliability=QosReliability(int(profile.reliability)),
               durability=QosDurability(int(profile.durability)), deadline=zero, lifespan=zero,
               liveliness=QosLiveliness(int(profile.liveliness)), liveliness_lease_duration=zero,
               avoid_ros_namespace_conventions=False)


# --------------------------------------------------------------------------------- reading
@dataclass(frozen=True)
class BagMessage:
    """One message of a bag: topic, type name, log time (ns), CDR bytes."""

    topic: str
    type: str
    log_ns: int
    data: bytes


def _check_bag_files(path: Path) -> None:
    """Before rosbags opens anything: ``metadata.yaml`` and every data file (those it lists, and
    every ``.mcap``/``.db3`` in the folder) are regular files within their size limits
    (:mod:`switchobs_core.files`): a FIFO blocks the reader forever, a huge file exhausts memory."""
    meta = path / "metadata.yaml"
    doc = load_yaml(meta, exc=BagError, what="bag metadata", max_bytes=MAX_METADATA_BYTES)
    info = doc.get("rosbag2_bagfile_information") if isinstance(doc, dict) else None
    listed = info.get("relative_file_paths") if isinstance(info, dict) else None
    names = {str(x) for x in listed if isinstance(x, str)} if isinstance(listed, list) else set()
    names |= {p.name for p in path.iterdir() if p.suffix in (".mcap", ".db3")}
    for name in sorted(names):
        f = path / name
        if f.resolve().parent != path.resolve():
            raise BagError(f"bag {path}: metadata.yaml lists a data file outside the bag folder ({name})")
        try:
            check_input(f, "bag data file", exc=BagError, max_bytes=MAX_BAG_BYTES)
        except FileNotFoundError:
            raise BagError(f"bag {path}: data file {name} listed in metadata.yaml is missing") from None


class BagIn:
    """A rosbag2 bag opened for reading (``with BagIn(path) as bag:``).

    ``bag.topics``: ``{topic: type}``; ``bag.counts``: ``{topic: message count}``;
    ``bag.storage``: ``"mcap"`` or ``"sqlite3"``.
    """

    def __init__(self, path: str | Path):
        from rosbags.rosbag2 import Reader

        self.path = Path(path)
        if not self.path.exists():
            raise BagError(f"bag {self.path}: no such file or folder")
        if not (self.path / "metadata.yaml").exists():
            raise BagError(f"bag {self.path}: not a rosbag2 bag folder (no metadata.yaml)")
        _check_bag_files(self.path)
        try:
            self._reader = Reader(self.path)
            self._reader.open()
        except Exception as err:
            raise BagError(f"bag {self.path}: cannot open ({one_line(err, with_type=True)}); "
                           "truncated or not a rosbag2 bag?") from None
        self.topics: dict[str, str] = {}
        self.counts: dict[str, int] = {}
        for c in self._reader.connections:
            self.topics.setdefault(c.topic, c.msgtype)
            self.counts[c.topic] = self.counts.get(c.topic, 0) + c.msgcount
        self.storage = "mcap" if any(self.path.glob("*.mcap")) else "sqlite3"
        self.message_count = sum(self.counts.values())

    def __enter__(self) -> BagIn:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        if getattr(self, "_reader", None) is not None:
            try:
                self._reader.close()
            except Exception:
                pass
            self._reader = None

    def require(self, needed: Mapping[str, str | Iterable[str]], what: str = "") -> None:
        """Check that every topic of ``needed`` is in the bag with (one of) the given type(s)."""
        for topic, types in needed.items():
            allowed = (types,) if isinstance(types, str) else tuple(types)
            if topic not in self.topics:
                have = ", ".join(f"{t} ({ty})" for t, ty in sorted(self.topics.items())) or "none"
                raise BagError(f"bag {self.path}: topic {topic} is missing{what} (the bag has: {have})")
            if self.topics[topic] not in allowed:
                raise BagError(f"bag {self.path}: topic {topic} has type {self.topics[topic]}; expected "
                               f"{' or '.join(allowed)}")

    def messages(self, topics: Iterable[str] | None = None, order: str = "log") -> list[BagMessage]:
        """The messages (of ``topics``, default all).

        ``order="log"``: by log time, ties in file order (see the module docstring), what a player
        publishes. ``order="file"``: as written, i.e. in receive order for a recorded bag (a
        recording on sim time of a looped replay has log times that go back; its passes stay apart
        in this order).

        Raises :class:`BagError` if the file ends early or a record is damaged, or if fewer
        messages than metadata.yaml counts could be read (a truncated file).
        """
        want = None if topics is None else set(topics)
        conns = [c for c in self._reader.connections if want is None or c.topic in want]
        out: list[tuple] = []
        got: dict[str, int] = {}
        try:
            for topic, msgtype, t, data in self._file_order({c.topic for c in conns}):
                out.append(BagMessage(topic, msgtype, t, bytes(data)))
                got[topic] = got.get(topic, 0) + 1
        except Exception as err:
            raise BagError(f"bag {self.path}: reading messages failed after {len(out)} messages "
                           f"({one_line(err, with_type=True)}); the file is truncated or damaged") from None
        for c in conns:
            if got.get(c.topic, 0) < self.counts.get(c.topic, 0):
                raise BagError(f"bag {self.path}: topic {c.topic} has {got.get(c.topic, 0)} readable messages "
                               f"but metadata.yaml counts {self.counts[c.topic]}; the file is truncated")
        if order != "file":
            out.sort(key=lambda m: m.log_ns)        # stable: ties stay in the file's order
        return out

    def log_order(self) -> Iterator[BagMessage]:
        """Every message, by log time, ties in the file's order (:meth:`messages` with ``order="log"``),
        read as it goes: an MCAP file's chunks one at a time (a message is handed on once no chunk still
        to read starts before it: the chunk index's start times), a SQLite file's rows by its query. A
        file without a chunk index (or several files) is read whole first. Raises :class:`BagError`
        as :meth:`messages` does, after the messages that could be read."""
        got: dict[str, int] = {}
        n = 0
        try:
            for m in self._log_order():
                got[m.topic] = got.get(m.topic, 0) + 1
                n += 1
                yield m
        except BagError:
            raise
        except Exception as err:
            raise BagError(f"bag {self.path}: reading messages failed after {n} messages "
                           f"({one_line(err, with_type=True)}); the file is truncated or damaged") from None
        for c in self._reader.connections:
            if got.get(c.topic, 0) < self.counts.get(c.topic, 0):
                raise BagError(f"bag {self.path}: topic {c.topic} has {got.get(c.topic, 0)} readable messages "
                               f"but metadata.yaml counts {self.counts[c.topic]}; the file is truncated")

    def _log_order(self) -> Iterator[BagMessage]:
        files = sorted(self.path.glob("*.mcap" if self.storage == "mcap" else "*.db3"))
        if len(files) != 1:
            yield from self.messages()
            return
        if self.storage != "mcap":
            import sqlite3
            db = sqlite3.connect(f"file:{files[0]}?mode=ro", uri=True)
            try:
                q = ("SELECT topics.name, topics.type, messages.timestamp, messages.data FROM messages "
                     "JOIN topics ON messages.topic_id = topics.id ORDER BY messages.timestamp, messages.id")
                for name, ty, t, data in db.execute(q):
                    yield BagMessage(name, ty, t, bytes(data))
            finally:
                db.close()
            return
        import heapq

        from mcap.data_stream import ReadDataStream
        from mcap.reader import breakup_chunk, make_reader
        from mcap.records import Chunk, Message

        with files[0].open("rb") as fh:
            reader = make_reader(fh)
            summary = reader.get_summary()
            if summary is None or not summary.chunk_indexes:
                yield from self.messages()
                return
            chunks = summary.chunk_indexes          # in the file's order (what messages() reads)
            later = [2**63] * (len(chunks) + 1)     # the earliest start of the chunks after each
            for j in range(len(chunks) - 1, -1, -1):
                later[j] = min(later[j + 1], chunks[j].message_start_time)
            topics = {cid: ch.topic for cid, ch in summary.channels.items()}
            heap: list[tuple[int, int, BagMessage]] = []
            seq = 0
            # a channel metadata.yaml does not list is skipped, as messages() skips it
            types = {cid: self.topics.get(t) for cid, t in topics.items()}
            for j, ci in enumerate(chunks):
                fh.seek(ci.chunk_start_offset + 1 + 8)
                if ci.compression == "":    # the records read straight from the chunk's bytes (mcap_records)
                    recs = message_records(fh.read(ci.chunk_length - 1 - 8))
                else:
                    recs = ((r.channel_id, r.log_time, r.data) for r in
                            breakup_chunk(Chunk.read(ReadDataStream(fh)), validate_crc=False) if isinstance(r, Message))
                for cid, log_time, data in recs:
                    ty = types.get(cid)
                    if ty is None:
                        continue
                    heapq.heappush(heap, (log_time, seq, BagMessage(topics[cid], ty, log_time, data)))
                    seq += 1
                bound = later[j + 1]
                while heap and heap[0][0] <= bound:
                    yield heapq.heappop(heap)[2]

    def _file_order(self, topics: set[str]):
        """``(topic, type, log_ns, data)`` in the order written (mcap: records; sqlite3: row ids)."""
        if self.storage == "mcap":
            from mcap.reader import make_reader
            for f in sorted(self.path.glob("*.mcap")):
                with f.open("rb") as fh:
                    for _schema, ch, msg in make_reader(fh).iter_messages(topics=sorted(topics),
                                                                          log_time_order=False):
                        yield ch.topic, self.topics[ch.topic], msg.log_time, msg.data
        else:
            import sqlite3
            for f in sorted(self.path.glob("*.db3")):
                db = sqlite3.connect(f"file:{f}?mode=ro", uri=True)
                try:
                    q = ("SELECT topics.name, topics.type, messages.timestamp, messages.data FROM messages "
                         "JOIN topics ON messages.topic_id = topics.id ORDER BY messages.id")
                    for name, ty, t, data in db.execute(q):
                        if name in topics:
                            yield name, ty, t, data
                finally:
                    db.close()


def deserialize(m: BagMessage, cls: type):
    """The rclpy message of ``m`` (:class:`BagError` naming the topic if the bytes are bad)."""
    from rclpy.serialization import deserialize_message
    try:
        return deserialize_message(m.data, cls)
    except Exception as err:
        raise BagError(f"topic {m.topic}: cannot deserialise a {m.type} at log time {m.log_ns} ns "
                       f"({one_line(err, with_type=True)}); truncated or damaged message") from None


def channel_message(m: BagMessage):
    """A channel-topic message of either type (:data:`CHANNEL_TYPES`), as the pipeline takes it;
    ``std_msgs/UInt8`` is read straight from its CDR bytes."""
    if m.type == CHANNEL_TYPES[0]:
        return deserialize(m, msg_class(m.type))
    return decode_uint8(m.data, lambda d: _uint8(m))


def _uint8(m: BagMessage):
    """``m`` deserialised as ``std_msgs/UInt8`` (a channel message :func:`~.cdr.decode_uint8` cannot read)."""
    from std_msgs.msg import UInt8

    return deserialize(m, UInt8)


# --------------------------------------------------------------------------------- writing
class BagOut:
    """A new rosbag2 bag (version 9) written with rosbags; ``with BagOut(path, "mcap") as out:``.

    ``out.add(topic, type_name)`` once per topic (the offered QoS written to metadata.yaml is
    the node contract's, :func:`qos_for`), then ``out.write(topic, log_ns, cdr_bytes)``.
    """

    def __init__(self, path: str | Path, storage: str = "mcap"):
        from rosbags.rosbag2 import StoragePlugin, Writer

        if storage not in STORAGES:
            raise BagError(f"storage '{storage}' is not supported; use one of {', '.join(STORAGES)}")
        self.path = Path(path)
        if self.path.exists():
            raise BagError(f"bag {self.path} exists already; choose a new folder (bags are never overwritten)")
        self.storage = storage
        self._typestore = None      # rosbags' Jazzy type store, made for a type msgdefs does not keep
        plugin = StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3
        fast_yaml()         # the same YAML, written without ruamel's emitter (switchobs_ros.bag.metadata_yaml)
        self._w = Writer(self.path, version=9, storage_plugin=plugin)
        try:
            self._w.open()
        except Exception as err:
            raise BagError(f"bag {self.path}: cannot create ({one_line(err, with_type=True)})") from None
        # the same bytes, fewer copies (switchobs_ros.bag.mcap_records); then a message goes to the storage
        # with the writer's own bookkeeping (Writer.write's, which also looks the connection up in a list)
        self._direct = fast_records(self._w) and self._w.compression_mode.name == "NONE"
        self._conns: dict[str, object] = {}
        self._defs: dict[str, tuple[str, str]] = {}     # per type: (message definition, RIHS01 hash)
        self._many: dict[tuple, tuple] = {}         # write_many: topics -> (connections, their ids)
        self.count = 0

    def __enter__(self) -> BagOut:
        return self

    def __exit__(self, exc_type, *exc) -> None:
        self.close()

    def add(self, topic: str, type_name_: str, qos=None) -> None:
        if topic in self._conns:
            return
        if type_name_ not in self._defs:        # 33 odometry topics share one type: its definition made once
            self._defs[type_name_] = self._definition(topic, type_name_)
        prof = qos if qos is not None else qos_for(topic)
        msgdef, rihs01 = self._defs[type_name_]
        self._conns[topic] = self._w.add_connection(topic, type_name_, msgdef=msgdef, rihs01=rihs01,
                                                    offered_qos_profiles=[_rosbags_qos(prof)])

    def _definition(self, topic: str, type_name_: str) -> tuple[str, str]:
        """``(msgdef, rihs01)`` of a connection's type: kept (:mod:`switchobs_ros.bag.msgdefs`), else from
        rosbags' Jazzy type store (with the switchobs_msgs types), made at its first use."""
        kept = definition(type_name_)
        if kept is not None:
            return kept
        if self._typestore is None:
            self._typestore = typestore()       # with switchobs_msgs: the estimator's typed outputs
        if type_name_ not in self._typestore.types:
            raise BagError(f"topic {topic}: type {type_name_} is not in the ROS 2 Jazzy type store")
        return from_store(self._typestore, type_name_)

    def write(self, topic: str, log_ns: int, data: bytes) -> None:
        conn = self._conns[topic]
        w = self._w
        if self._direct:
            ts = int(log_ns)
            w.storage.write(conn, ts, data)
            w.counts[conn.id] += 1
            if ts < w.min_timestamp:
                w.min_timestamp = ts
            if ts > w.max_timestamp:
                w.max_timestamp = ts
        else:
            w.write(conn, int(log_ns), data)
        self.count += 1

    def write_many(self, topics: list[str], log_ns: int, datas: list) -> None:
        """:meth:`write` of ``datas[k]`` on ``topics[k]`` in turn, all at ``log_ns`` (the same file);
        a ``datas[k]`` may be a tuple of pieces of one message's bytes (:meth:`.cdr.Template.pieces`)."""
        if not self._direct:
            for topic, data in zip(topics, datas):
                self.write(topic, log_ns, b"".join(data) if data.__class__ is tuple else data)
            return
        w = self._w
        ts = int(log_ns)
        key = tuple(topics)
        hit = self._many.get(key)
        if hit is None:         # a tick's topics repeat: their connections and ids looked up once
            if len(self._many) >= 64:
                self._many.clear()
            conns = [self._conns[t] for t in topics]
            hit = self._many[key] = (conns, [c.id for c in conns])
        conns, ids = hit
        w.storage.write_many(conns, ts, datas)
        counts = w.counts
        for cid in ids:
            counts[cid] += 1
        if ts < w.min_timestamp:
            w.min_timestamp = ts
        if ts > w.max_timestamp:
            w.max_timestamp = ts
        self.count += len(conns)

    def close(self) -> None:
        if self._w is not None:
            self._w.close()
            self._w = None

