"""The RViz markers' publisher (``~/markers``), created right after the node's first estimate.

``visualization_msgs/MarkerArray``'s type support (it loads ``sensor_msgs``' and ``geometry_msgs``'
libraries) and its DataWriter take 15-25 ms of CPU (bench/RESULTS.md), which a start that made the
publisher with the others would spend before its first answer. Nothing is published on the markers
before the first estimate, so the publisher is made right after it (:meth:`OutputsMixin._publish_all
<switchobs_ros.outputs.OutputsMixin._publish_all>`): the topic appears a few milliseconds after the
first estimate, and a subscriber gets the markers of the estimates published once it is matched
(:mod:`switchobs_ros.demand`), as a subscriber that comes later does. The first estimate's markers
are therefore never published; the second answer waits for the publisher's creation.
"""

from __future__ import annotations

from typing import Any

from . import qos

__all__ = ["LateMarkersMixin"]


class LateMarkersMixin:
    """The markers' publisher and writer; the node sets ``markers_pending`` in ``_create_interfaces``
    (a system with bodies) and provides ``bodies``, ``frame``, ``_optional_writer`` and ``pipeline``."""

    pub_markers: Any = None
    markers_pending = False

    @property
    def w_markers(self) -> Any:
        """RViz markers' writer (:class:`msg_bridge.markers.RawMarkersWriter`), ``None`` for a system
        without bodies."""
        if not self.bodies:
            return None

        def make() -> Any:
            from msg_bridge.markers import RawMarkersWriter
            return RawMarkersWriter(self.bodies, self.frame)
        return self._optional_writer("markers", make)

    def _create_markers_publisher(self) -> None:
        """``~/markers`` (reliable, no default middleware event handlers, as the node's other publishers);
        a failure is counted as the ``publish`` internal error and not tried again."""
        self.markers_pending = False
        try:
            from rclpy.event_handler import PublisherEventCallbacks
            from visualization_msgs.msg import MarkerArray

            self.pub_markers = self.create_publisher(
                MarkerArray, "~/markers", qos.OUTPUT,
                event_callbacks=PublisherEventCallbacks(use_default_callbacks=False))
        except Exception as err:
            self.pipeline.internal_error("publish", err)
