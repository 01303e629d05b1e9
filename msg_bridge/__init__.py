"""msg_bridge: ROS 2 messages <-> numpy, and validation of what arrives.

Imports message types (and from the core: its exception base, and for ``inputs`` the system
and the bounded YAML loader) only: no node, no executor, no numerics beyond reshaping
(docs/architecture.md). Channel numbers are the paper's 1-based numbers
everywhere here, as on the ``camera/active_channel`` topic.

Modules
-------
stamps    header stamps <-> integer nanoseconds
convert   PoseStamped <-> planar position, labelled Float64MultiArray (state, envelope,
          truth), per-body nav_msgs/Odometry
validate  checks of incoming messages returning a :class:`Rejection` with a
          :class:`Reason` code; the error types :class:`BridgeError`, :class:`SpecError`
parse     a stamped input's one checked form ``(sec, nanosec, frame_id, values)`` from its
          serialised bytes (:class:`RawReader`, no message built) or a message (:class:`Parser`)
fields    one converter per sensor message type: :class:`FieldReader` (message ->
          ``(stamp_ns, frame_id, y)``) and :class:`FieldWriter` (values -> message)
inputs    input specifications: topic, type, fields -> output rows, and how the channel is
          known (:class:`InputSpecs`, :func:`load_inputs`)
control   the control topic of a system with inputs: type, fields -> u (:class:`ControlSpec`)
markers   ``~/markers`` for RViz (:class:`MarkersWriter`): per body its position, 2-sigma
          ellipse, the guaranteed bound's circle, the body in view highlighted
typed     the typed outputs ``switchobs_msgs/StateEstimate`` and ``ErrorBounds``: writers,
          readers, and their registration in a rosbags type store. Not imported here (it needs
          the interface package that scripts/bootstrap.sh builds): ``from msg_bridge.typed
          import ...``

Together, ``fields`` and ``inputs`` give the observer its measurement
``(stamp_ns, channel, rows, y)`` from any supported topic.
"""

from .control import CONTROL_TOPIC, ControlSpec, input_labels
from .convert import (
    STAMP_PAD,
    UNESTIMATED_VARIANCE,
    Body,
    LabelledArray,
    LabelledArrayWriter,
    OdometryWriter,
    bodies,
    body_odometry,
    covariance_labels,
    describe_bodies,
    envelope_labels,
    labelled_array,
    odometry_covariances,
    pose_to_xy,
    state_odometries,
    unpack_labelled,
    unused_states,
    xy_to_pose,
)
from .fields import (
    LABELLED_ARRAY,
    MAX_FIELDS,
    SUPPORTED_TYPES,
    FieldReader,
    FieldWriter,
    canonical_type,
    float64_fields,
    message_class,
)
from .inputs import (
    CHANNEL_TOPIC,
    MAX_SOURCES,
    InputSource,
    InputSpecs,
    check_topic,
    default_inputs,
    load_inputs,
    parse_inputs,
    ros_topic_error,
)
from .parse import RAW_TYPES, Parser, RawReader, raw_readable
from .stamps import NS_PER_S, float_time_ns, ns_to_stamp, stamp_to_ns, stamp_to_sec, time_ns
from .validate import (
    BridgeError,
    Reason,
    Rejection,
    SpecError,
    channel_value,
    check_after_switch,
    check_channel,
    check_pose,
    check_stamp,
    check_time,
    check_values,
    read_channel,
)

__all__ = [
    "CHANNEL_TOPIC",
    "CONTROL_TOPIC",
    "ControlSpec",
    "input_labels",
    "LABELLED_ARRAY",
    "MAX_FIELDS",
    "SUPPORTED_TYPES",
    "FieldReader",
    "FieldWriter",
    "InputSource",
    "InputSpecs",
    "MAX_SOURCES",
    "SpecError",
    "canonical_type",
    "check_topic",
    "default_inputs",
    "float64_fields",
    "load_inputs",
    "message_class",
    "parse_inputs",
    "ros_topic_error",
    "STAMP_PAD",
    "Body",
    "BridgeError",
    "LabelledArray",
    "LabelledArrayWriter",
    "MarkersWriter",
    "Parser",
    "RAW_TYPES",
    "RawReader",
    "raw_readable",
    "OdometryWriter",
    "Reason",
    "Rejection",
    "bodies",
    "check_after_switch",
    "body_odometry",
    "covariance_labels",
    "describe_bodies",
    "unused_states",
    "odometry_covariances",
    "UNESTIMATED_VARIANCE",
    "channel_value",
    "check_channel",
    "read_channel",
    "check_pose",
    "check_stamp",
    "check_time",
    "check_values",
    "envelope_labels",
    "labelled_array",
    "NS_PER_S",
    "float_time_ns",
    "ns_to_stamp",
    "pose_to_xy",
    "stamp_to_ns",
    "stamp_to_sec",
    "time_ns",
    "state_odometries",
    "unpack_labelled",
    "xy_to_pose",
]


def __getattr__(name: str) -> object:
    """``MarkersWriter`` (:mod:`msg_bridge.markers`) imported at its first use: ``visualization_msgs``' message
    classes (3-5 ms) are not needed before the estimator's first estimate (:mod:`switchobs_ros.late_markers`)."""
    if name == "MarkersWriter":
        from .markers import MarkersWriter
        return MarkersWriter
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")

