"""Input specifications: which topics feed which output rows of which channel.

The observer needs the measurement ``(stamp_ns, channel, rows, y)`` and nothing else. An
input specification says, per topic, the message type, the float64 fields read from it
(:class:`~msg_bridge.fields.FieldReader`) and the output rows of the channel's
``y_c = C_c x`` they feed, and how the channel of a sample is known:

* ``channel: c`` -- the topic belongs to channel c (one topic per channel: the topic is the
  channel);
* ``channel`` omitted (None) and *shared* rows -- the source measures the same thing whatever
  the channel (its rows have equal ``C`` rows in every channel, e.g. the camera's own pose): it
  feeds those rows of whichever channel is active at the sample's stamp;
* ``channel`` omitted and rows that differ between channels (the paper's ``target/pose``, which
  shows whichever agent is in view) -- the channel comes from ``channel_topic``
  (``std_msgs/UInt8``, 1..N), which is then required.

YAML: a top-level ``inputs:`` section of the system file, beside ``noise:``::

    inputs:
      channel_topic: camera/active_channel      # optional
      sources:
        - {topic: camera/pose, type: geometry_msgs/PoseStamped,
           fields: [pose.position.x, pose.position.y], rows: [camera.p_x, camera.p_y]}
        - {topic: target/pose, type: geometry_msgs/PoseStamped,
           fields: [pose.position.x, pose.position.y], rows: [2, 3]}

A system with inputs (``B u``) takes its commands on a control topic: the section's ``control:``
key, or ``~/control`` (:mod:`msg_bridge.control`).

``rows`` are 0-based row indices of ``C_c`` or output labels (``system.output_labels``); a
label must exist in every channel the source serves. Without an ``inputs:`` section the paper's
interface is the default (:func:`default_inputs`). Every mistake is a :class:`SpecError` with
one line naming the source and what to do.
"""

from __future__ import annotations

import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from switchobs_core.loading import load_yaml
from switchobs_core.model.scenarios import SCENARIOS
from switchobs_core.model.system import LTISystem

from .control import ControlSpec, default_control, parse_control
from .fields import FieldReader
from .validate import SpecError

__all__ = [
    "CHANNEL_TOPIC",
    "InputSource",
    "InputSpecs",
    "MAX_SOURCES",
    "check_topic",
    "default_inputs",
    "load_inputs",
    "parse_inputs",
    "ros_topic_error",
]

#: The paper's active-channel topic (std_msgs/UInt8, 1..N).
CHANNEL_TOPIC = "camera/active_channel"

#: Most sources a specification may hold (and never more than the rows of all channels: each
#: source feeds at least one row, and no row is fed twice).
MAX_SOURCES = 1024

_SECTION_KEYS = ("channel_topic", "sources", "control")
_SOURCE_KEYS = ("topic", "type", "fields", "rows", "channel")
_TOKEN = r"[A-Za-z_][A-Za-z0-9_]*"
_TOPIC = re.compile(rf"{_TOKEN}(/{_TOKEN})*")

_EXAMPLE = ("inputs: {sources: [{topic: left/point, type: geometry_msgs/PointStamped, channel: 1, "
            "fields: [point.x], rows: [0]}, ...]}")


def _shown(name: str) -> str:
    """``name`` for a message: whole when short, else its start and its length."""
    return repr(name) if len(name) <= 60 else f"'{name[:40]}...' ({len(name)} characters)"


def ros_topic_error(name: str, namespace: str = "/") -> str | None:
    """Why ROS refuses the topic ``name`` of a node in ``namespace`` (None: it takes it): rclpy's own
    validation of the expanded name (:func:`rclpy.expand_topic_name.expand_topic_name`,
    :func:`rclpy.validate_full_topic_name.validate_full_topic_name`: characters, tokens, the length
    limit of the middleware), the checks ``create_subscription`` makes. No node is needed."""
    from rclpy.exceptions import InvalidTopicNameException
    from rclpy.expand_topic_name import expand_topic_name
    from rclpy.validate_full_topic_name import validate_full_topic_name
    try:
        validate_full_topic_name(expand_topic_name(name, "estimator", namespace))
    except InvalidTopicNameException as err:      # "Invalid topic name: <why>:\n  '<name>'\n  ^"
        return str(err).split("\n", 1)[0].removeprefix("Invalid topic name: ").rstrip(":")
    except ValueError as err:                     # "topic name '<name>' is invalid: <why>, at <file>"
        return str(err).rpartition(" is invalid: ")[2].rsplit(", at ", 1)[0]
    return None


def check_topic(name: Any, where: str, namespace: str = "/") -> str:
    """A relative ROS topic name (tokens of letters, digits and '_' not starting with a digit,
    joined by single '/') that ROS takes in ``namespace`` (:func:`ros_topic_error`: e.g. at most
    247 characters once expanded); else :class:`SpecError` naming ``where``."""
    if not isinstance(name, str) or not _TOPIC.fullmatch(name):
        shown = _shown(name) if isinstance(name, str) else repr(name)
        raise SpecError(f"{where}: {shown} is not a valid relative topic name (letters, digits, '_' and single "
                        "'/' between tokens; no leading '/' or '~', no spaces; a token must not start with a "
                        "digit), e.g. camera/pose")
    why = ros_topic_error(name, namespace)
    if why is not None:
        raise SpecError(f"{where}: {_shown(name)} is not a valid topic name: ROS: {why}")
    return name


@dataclass(frozen=True)
class InputSource:
    """One subscribed topic: its message type, the fields read and the output rows they feed.

    ``rows[k]`` is the 0-based row of ``y_c = C_c x`` that ``fields[k]`` feeds in channel
    ``channel``; for a source of every channel (``channel`` None) it is the row in channel 1,
    and :meth:`rows_for` gives it per channel (output labels may sit at different rows in
    different channels). ``shared`` says the rows measure the same thing in every channel
    (equal rows of every ``C_c``), so the sample does not need the channel to be known.
    :func:`parse_inputs` and :func:`default_inputs` fill ``channel_rows`` and ``shared``; a
    source built by hand without ``channel_rows`` feeds ``rows`` in every channel it serves.
    """

    topic: str
    type: str
    fields: tuple[str, ...]
    rows: tuple[int, ...]
    channel: int | None
    reader: FieldReader = field(compare=False, repr=False)
    channel_rows: tuple[tuple[int, ...], ...] = ()
    shared: bool = False

    def serves(self, channel: int) -> bool:
        """Whether this source feeds rows of ``channel`` (1-based)."""
        return self.channel is None or self.channel == channel

    def rows_for(self, channel: int) -> tuple[int, ...]:
        """The rows of channel ``channel`` (1-based) that the fields feed; () if it does not serve it."""
        if not self.serves(channel):
            return ()
        return self.channel_rows[channel - 1] if self.channel_rows else self.rows

    def describe(self) -> str:
        """One line: topic, type, fields -> rows, and how the channel is known."""
        if self.channel is not None:
            how = f"channel {self.channel}"
        elif self.shared:
            how = "every channel (shared rows)"
        else:
            how = "channel from the channel topic"
        rows = {r for r in self.channel_rows if r}
        rows_txt = str(list(self.rows)) if len(rows) <= 1 else \
            "; ".join(f"{c}: {list(r)}" for c, r in enumerate(self.channel_rows, start=1))
        return f"{self.topic} ({self.type}) {list(self.fields)} -> rows {rows_txt}, {how}"


@dataclass(frozen=True)
class InputSpecs:
    """The inputs of a system: sources, the channel topic and the channels no source feeds.

    Each source turns a message into (part of) the measurement ``(stamp_ns, channel, rows, y)``:
    its reader gives ``stamp_ns`` and ``y``, :meth:`InputSource.rows_for` the rows, and the channel
    is the source's own, or the active one at ``stamp_ns`` (docs/tutorials/own-system.md, "Input specifications").
    """

    sources: tuple[InputSource, ...]
    channel_topic: str | None
    uncovered: tuple[int, ...] = ()
    control: ControlSpec | None = None      # the known input u (msg_bridge.control)

    def shared_rows(self, channel: int) -> tuple[int, ...]:
        """The rows of ``channel`` (1-based) fed by channel-independent (shared) sources, in source order."""
        return tuple(r for s in self.sources if s.shared for r in s.rows_for(channel))

    def uncovered_warning(self) -> str:
        """One line saying which channels no source feeds ('' if none): accepted, and said at
        start-up (the node's log, ``switchobs_bag estimate``'s warning)."""
        if not self.uncovered:
            return ""
        many = len(self.uncovered) > 1
        return (f"no source feeds channel{'s' if many else ''} {', '.join(map(str, self.uncovered))} (the input "
                f"specification): {'their' if many else 'its'} samples never arrive, so nothing is measured while "
                f"{'they are' if many else 'it is'} active")

    def describe(self) -> str:
        """A few lines for logs and diagnostics."""
        lines = [f"inputs: {len(self.sources)} source(s), channel topic "
                 f"{self.channel_topic if self.channel_topic else '(none: each topic is its channel)'}"]
        lines += [f"  {s.describe()}" for s in self.sources]
        if self.uncovered:
            lines.append(f"  no source feeds channel(s) {list(self.uncovered)}")
        if self.control is not None:
            lines.append(f"  {self.control.describe()}")
        return "\n".join(lines)


# ----------------------------------------------------------------------------- parsing


def _resolve_rows(rows: Sequence[Any], channel: int, system: LTISystem, where: str) -> tuple[int, ...]:
    """Row indices of ``rows`` (0-based ints or output labels) in ``channel`` (1-based)."""
    labels = system.output_labels[channel - 1]
    p = len(labels)
    index = {lab: k for k, lab in enumerate(labels)}
    out = []
    for r in rows:
        if isinstance(r, bool) or not isinstance(r, (int, np.integer, str)):
            raise SpecError(f"{where}: row {r!r} must be a 0-based row index or an output label")
        if isinstance(r, str):
            if r not in index:
                raise SpecError(f"{where}: channel {channel} has no output {r!r}; its outputs: {list(labels)}")
            out.append(index[r])
        elif not 0 <= r < p:
            raise SpecError(f"{where}: row {r} is out of range for channel {channel} (rows 0..{p - 1}: "
                            f"{list(labels)})")
        else:
            out.append(int(r))
    return tuple(out)


def _make_source(topic: str, reader: FieldReader, channel_rows: Sequence[Sequence[int]],
                 channel: int | None, system: LTISystem) -> InputSource:
    """An :class:`InputSource` from checked parts; ``channel_rows[c - 1]`` are the rows in channel c."""
    crs = tuple(tuple(r) for r in channel_rows)
    served = [c for c in range(1, system.N + 1) if channel is None or c == channel]
    rows = crs[served[0] - 1]
    shared = channel is None and all(np.array_equal(system.C[c - 1][list(crs[c - 1])], system.C[0][list(crs[0])])
                                     for c in served)
    return InputSource(topic, reader.type, reader.fields, rows, channel, reader, crs, shared)


def _parse_source(i: int, spec: Any, system: LTISystem, source: str) -> InputSource:
    where = f"{source}.sources[{i}]"
    if not isinstance(spec, Mapping):
        raise SpecError(f"{where}: must be a mapping with keys {', '.join(_SOURCE_KEYS)}; got {spec!r}")
    named = f"{where} ({spec['topic']})" if isinstance(spec.get("topic"), str) else where
    unknown = sorted(map(str, set(spec) - set(_SOURCE_KEYS)))
    if unknown:
        raise SpecError(f"{named}: unknown key(s) {unknown} (known: {', '.join(_SOURCE_KEYS)})")
    missing = [k for k in ("topic", "type", "fields", "rows") if k not in spec]
    if missing:
        raise SpecError(f"{named}: missing key(s) {missing} (each source needs topic, type, fields, rows)")
    topic = check_topic(spec["topic"], f"{where}.topic")
    where = named
    try:
        reader = FieldReader(spec["type"], spec["fields"])
    except SpecError as err:
        raise SpecError(f"{where}: {err}") from None
    rows = spec["rows"]
    if isinstance(rows, (str, bytes)) or not isinstance(rows, Sequence):
        raise SpecError(f"{where}: rows must be a list (row indices or output labels); got {rows!r}")
    if len(rows) != len(reader.fields):
        raise SpecError(f"{where}: {len(reader.fields)} field(s) but {len(rows)} row(s); give one row per field")
    channel = spec.get("channel")
    N = system.N
    if channel is not None:
        if isinstance(channel, bool) or not isinstance(channel, (int, np.integer)) or not 1 <= channel <= N:
            raise SpecError(f"{where}: channel {channel!r} is not one of the system's channels 1..{N} "
                            "(omit it for a source of every channel)")
        channel = int(channel)
    try:
        crs = [_resolve_rows(rows, c, system, where) if channel is None or c == channel else ()
               for c in range(1, N + 1)]
    except SpecError as err:
        if channel is None:         # a source of every channel: say how to narrow it
            raise SpecError(f"{err}; a source without 'channel' feeds every channel, so its rows must exist in "
                            "each (or give it a 'channel')") from None
        raise
    for c, r in enumerate(crs, start=1):
        seen: set[int] = set()
        dup = next((k for k in r if k in seen or seen.add(k)), None)     # linear: one set
        if dup is not None:
            raise SpecError(f"{where}: row {dup} of channel {c} is given twice")
    return _make_source(topic, reader, crs, channel, system)


def _topic_used(source: str, i: int, topic: str, first: int) -> SpecError:
    return SpecError(f"{source}.sources[{i}] ({topic}): topic already used by sources[{first}]; one source per topic "
                     "(list all its fields in one source)")


def _check_specs(sources: Sequence[InputSource], channel_topic: str | None, system: LTISystem,
                 source: str) -> InputSpecs:
    """Cross-source checks; the :class:`InputSpecs`."""
    if not sources:
        raise SpecError(f"{source}: no sources; give at least one, e.g. {_EXAMPLE}")
    seen: dict[str, int] = {}
    for i, s in enumerate(sources):
        if s.topic in seen:
            raise _topic_used(source, i, s.topic, seen[s.topic])
        seen[s.topic] = i
        if s.topic == channel_topic:
            raise SpecError(f"{source}.sources[{i}] ({s.topic}): the topic is also the channel_topic; "
                            "give them different topics")
        if s.channel is None and not s.shared and channel_topic is None:
            raise SpecError(f"{source}.sources[{i}] ({s.topic}): its rows differ between channels, so one topic "
                            "carries several channels: give channel_topic (std_msgs/UInt8, 1..N) or a 'channel' "
                            "per source (one topic per channel)")
    uncovered = []
    for c in range(1, system.N + 1):
        fed: dict[int, int] = {}
        for i, s in enumerate(sources):
            for r in s.rows_for(c):
                if r in fed:
                    raise SpecError(f"{source}.sources[{i}] ({s.topic}): row {r} of channel {c} is already fed by "
                                    f"sources[{fed[r]}] ({sources[fed[r]].topic}); each row has one source")
                fed[r] = i
        if not fed:
            uncovered.append(c)
    return InputSpecs(tuple(sources), channel_topic, tuple(uncovered))


def parse_inputs(section: Mapping | None, system: LTISystem, *, source: str = "inputs",
                 camera_body: str = "camera") -> InputSpecs:
    """The :class:`InputSpecs` of an ``inputs:`` mapping (module docstring) for ``system``.

    ``section`` None (no section, or an empty one) gives :func:`default_inputs`. ``source``
    prefixes every error message (e.g. ``"cart_pair.yaml: inputs"``).

    Raises
    ------
    SpecError
        One line naming the source (index and topic) and what to do: an unknown key or type,
        a field the type lacks, rows out of range or not among a channel's outputs, fields and
        rows of different lengths, a row of one channel fed twice, a topic used twice, an
        invalid topic name, a channel outside 1..N, a topic carrying several channels without a
        ``channel_topic``. A channel that no source feeds is not an error: see
        :attr:`InputSpecs.uncovered`.
    """
    if section is None:
        return default_inputs(system, camera_body)
    if not isinstance(section, Mapping):
        raise SpecError(f"{source}: must be a mapping with 'sources' (and optionally 'channel_topic'); "
                        f"got {section!r}")
    unknown = sorted(map(str, set(section) - set(_SECTION_KEYS)))
    if unknown:
        raise SpecError(f"{source}: unknown key(s) {unknown} (known: {', '.join(_SECTION_KEYS)})")
    ct = section.get("channel_topic")
    channel_topic = None if ct is None else check_topic(ct, f"{source}.channel_topic")
    specs = section.get("sources")
    if not isinstance(specs, Sequence) or isinstance(specs, (str, bytes)):
        raise SpecError(f"{source}: 'sources' must be a list of sources, e.g. {_EXAMPLE}")
    limit = min(MAX_SOURCES, sum(int(p) for p in system.p))
    if len(specs) > limit:
        raise SpecError(f"{source}: {len(specs)} sources; the system's channels have {sum(system.p)} rows in all, so "
                        f"at most {limit} sources (each feeds at least one row, no row twice)")
    sources: list[InputSource] = []
    seen: dict[str, int] = {}
    for i, s in enumerate(specs):      # a topic used twice is found at its second use, not after parsing all
        sources.append(_parse_source(i, s, system, source))
        t = sources[-1].topic
        if t in seen:
            raise _topic_used(source, i, t, seen[t])
        seen[t] = i
    return _with_control(_check_specs(sources, channel_topic, system, source),
                         parse_control(section.get("control"), system, f"{source}.control"), source)


def default_inputs(system: LTISystem, camera_body: str = "camera") -> InputSpecs:
    """The paper's interface: ``camera/pose`` and ``target/pose`` (PoseStamped, the planar
    position) and the active channel on ``camera/active_channel``.

    Fits a system whose every channel outputs ``<camera>.p_x, <camera>.p_y, <target>.p_x,
    <target>.p_y`` (one target body per channel; labels in any order), like ``paper`` and
    ``camera_agents``; any other system needs an ``inputs:`` section (:class:`SpecError`).
    """
    cam_rows, tgt_rows = [], []
    for i, labels in enumerate(system.output_labels, start=1):
        parts = [lab.rpartition(".") for lab in labels]
        cam = {q: k for k, (b, _, q) in enumerate(parts) if b == camera_body}
        tgt = {q: k for k, (b, _, q) in enumerate(parts) if b != camera_body}
        targets = {b for b, _, _ in parts} - {camera_body}
        if len(labels) != 4 or set(cam) != {"p_x", "p_y"} or set(tgt) != {"p_x", "p_y"} or len(targets) != 1:
            raise SpecError(f"system '{system.name}' has no inputs: section and does not fit the default "
                            f"camera/target topics: channel {i} outputs {list(labels)}; expected {camera_body}.p_x, "
                            f"{camera_body}.p_y and <target>.p_x, <target>.p_y; add an inputs: section to the "
                            f"system file, e.g. {_EXAMPLE}")
        cam_rows.append((cam["p_x"], cam["p_y"]))
        tgt_rows.append((tgt["p_x"], tgt["p_y"]))
    reader = FieldReader("geometry_msgs/msg/PoseStamped", ("pose.position.x", "pose.position.y"))
    sources = [_make_source("camera/pose", reader, cam_rows, None, system),
               _make_source("target/pose", reader, tgt_rows, None, system)]
    return _with_control(_check_specs(sources, CHANNEL_TOPIC, system, "default inputs"), default_control(system),
                         "default inputs")


def _with_control(specs: InputSpecs, control: ControlSpec | None, source: str) -> InputSpecs:
    """``specs`` with its control topic (one that no source or the channel topic uses)."""
    if control is not None and control.topic in {s.topic for s in specs.sources} | {specs.channel_topic}:
        raise SpecError(f"{source}.control: topic {control.topic} is also an input source's or the channel topic; "
                        "give the commands a topic of their own")
    return replace(specs, control=control)


def _read_section(path: str, what: str) -> tuple[bool, Any]:
    """``(present, section)`` of the ``inputs:`` key of the YAML file ``path``."""
    try:
        data = load_yaml(path, exc=SpecError, what=what)
    except FileNotFoundError:
        raise SpecError(f"{what} {path} does not exist") from None
    if not isinstance(data, Mapping):
        return False, None
    return "inputs" in data, data.get("inputs")


def load_inputs(system_param: str, system: LTISystem, *, camera_body: str = "camera",
                override: str = "") -> InputSpecs:
    """The inputs of a system: ``override`` (a YAML file with an ``inputs:`` section, e.g. a
    params override), else the ``inputs:`` section of the system file ``system_param``, else
    :func:`default_inputs`.
    """
    if override:
        present, section = _read_section(override, "inputs file")
        if not present:
            raise SpecError(f"inputs file {override} has no top-level 'inputs:' section, e.g. {_EXAMPLE}")
        return parse_inputs(section, system, source=f"{override}: inputs", camera_body=camera_body)
    s = str(system_param)
    if s not in SCENARIOS and Path(s).is_file():
        present, section = _read_section(s, "system file")
        if present:
            return parse_inputs(section, system, source=f"{s}: inputs", camera_body=camera_body)
    return default_inputs(system, camera_body)
