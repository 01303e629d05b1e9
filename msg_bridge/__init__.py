"""msg_bridge: ROS 2 messages <-> numpy, and validation of what arrives.

Imports message types only: no node, no executor, no numerics beyond reshaping
(docs/architecture.md). Channel numbers are the paper's 1-based numbers
everywhere here, as on the ``camera/active_channel`` topic.

Modules
-------
stamps    header stamps <-> integer nanoseconds
convert   PoseStamped <-> planar position, labelled Float64MultiArray (state, envelope,
          truth), per-body nav_msgs/Odometry
validate  checks of incoming messages returning a :class:`Rejection` with a
          :class:`Reason` code
"""

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
    envelope_labels,
    labelled_array,
    odometry_covariances,
    pose_to_xy,
    state_odometries,
    unpack_labelled,
    xy_to_pose,
)
from .inputs import message_class
from .stamps import ns_to_stamp, stamp_to_ns, stamp_to_sec
from .validate import (
    BridgeError,
    Reason,
    Rejection,
    check_after_switch,
    check_channel,
    check_pose,
    check_stamp,
    check_values,
)

__all__ = [
    "STAMP_PAD",
    "Body",
    "BridgeError",
    "LabelledArray",
    "LabelledArrayWriter",
    "OdometryWriter",
    "Reason",
    "Rejection",
    "bodies",
    "check_after_switch",
    "body_odometry",
    "covariance_labels",
    "odometry_covariances",
    "UNESTIMATED_VARIANCE",
    "check_channel",
    "check_pose",
    "check_stamp",
    "check_values",
    "envelope_labels",
    "labelled_array",
    "message_class",
    "ns_to_stamp",
    "pose_to_xy",
    "stamp_to_ns",
    "stamp_to_sec",
    "state_odometries",
    "unpack_labelled",
    "xy_to_pose",
]
