"""The estimator's outputs: each estimate published on ``~/state`` and, at their decimation and only
while a subscription is matched to them, on the optional outputs (``~/envelope``, ``~/covariance``,
one ``nav_msgs/Odometry`` per body, the typed messages, the RViz markers).

:class:`OutputsMixin` is the publishing half of :class:`~switchobs_ros.estimator.EstimatorMixin`:

* messages of a fixed layout are published as serialised bytes whose numbers are rewritten in
  place (:mod:`msg_bridge.raw`: the state, the envelope, the covariance, every body's odometry in
  one buffer, the typed state estimate); ``~/error_bounds`` (its reasons change length) and the
  markers are Python messages reused from one estimate to the next;
* ``output.<name>_every = m`` publishes the ``k``-th estimate (from 0) on that output when
  ``k % m == 0`` (0: never);
* ``P`` is formed only for an estimate that a listened output carrying it takes
  (:meth:`OutputsMixin._covariance_due`, asked by the pipeline before each estimate reads ``P``):
  with ``output.covariance_every: 5`` and the odometry every 5, four estimates in five cost no
  covariance at all.
"""

from __future__ import annotations

from typing import Any

import msg_bridge as mb
from msg_bridge.raw import RawLabelledArrayWriter

from .demand import listened, listened_each
from .late_markers import LateMarkersMixin
from .pipeline import Estimate

__all__ = ["OutputsMixin", "channel_bodies", "send"]


def send(pub: Any, data: Any) -> None:
    """Publish ``data`` on ``pub``: serialised ``bytes`` straight to rclpy's publisher handle
    (``publish_raw``: what ``Publisher.publish(bytes)`` calls after a type test and entering the
    handle, 0.7-1.4 us more per call measured here; the node's publishers are destroyed only by its
    own spinning thread, between publications), and so a writer's own ``bytearray`` (its ``write``:
    ``publish_raw`` copies it before it returns, so the writer may rewrite it after), a message
    object through ``Publisher.publish``."""
    if type(data) in _SERIALISED:
        pub.handle.publish_raw(data)
    else:
        pub.publish(data)


_SERIALISED = (bytes, bytearray)


def channel_bodies(system: Any, bodies: Any) -> dict[int, str]:
    """The body each channel sees (the one whose outputs belong to that channel alone, as
    ``agent2`` for channel 2 of the camera scenarios): ``{channel: body name}``, channels whose
    outputs name no such body left out (the markers then highlight none)."""
    names = {b.name for b in bodies}
    common = set.intersection(*(set(o) for o in system.output_labels)) if system.N else set()
    out = {}
    for c, labels in enumerate(system.output_labels, start=1):
        own = {lab.rpartition(".")[0] for lab in labels if lab not in common} & names
        if len(own) == 1:
            out[c] = own.pop()
    return out


class OutputsMixin(LateMarkersMixin):
    """Publishing the estimates (module docstring); the node provides the publishers, the writers,
    ``every`` (``output.*_every``), ``published`` (counts per output), ``n_published``, ``demand``
    and ``pipeline``."""

    @property
    def w_cov(self) -> RawLabelledArrayWriter:
        """The covariance's writer (``~/covariance``: n^2 labels, 17 424 at n = 132), built at its first
        use as the other optional outputs' (the node's ``_optional_writer``)."""
        return self._optional_writer("cov", lambda: RawLabelledArrayWriter(mb.covariance_labels(self.state_labels)))

    def _covariance_carriers(self) -> list:
        """``(output, publisher)`` of the outputs whose messages carry ``P``, those published at all
        (for :class:`~switchobs_ros.demand.Demand`)."""
        ev = self.every     # (the node may recreate its publishers: read them each time)
        pubs = (("covariance", getattr(self, "pub_cov", None)),
                ("typed", self.pub_typed[0] if getattr(self, "pub_typed", ()) else None),
                ("markers", getattr(self, "pub_markers", None)),
                *(("odometry", p) for p in getattr(self, "pub_odom", [])))
        return [(k, p) for k, p in pubs if ev[k] and p is not None]

    def _covariance_due(self, i: int) -> bool:
        """Whether the ``i``-th estimate of the pipeline's present call (the ``n_published + i``-th)
        goes out on a listened output that carries ``P`` (``output.*_every``; the outputs listened:
        :meth:`Demand.covariance_wanted <switchobs_ros.demand.Demand.covariance_wanted>`, asked here,
        as the estimate is about to read ``P``)."""
        if not self.demand.covariance_wanted():
            return False
        k, ev = self.n_published + i, self.every
        return any(k % ev[kind] == 0 for kind in self.demand.kinds)

    def _publish_all(self, estimates: list[Estimate]) -> None:
        """Publish each estimate: ``~/state`` always, the other outputs at their decimation
        (``output.*_every``) and only while a subscription is matched to them (:mod:`switchobs_ros.demand`)."""
        if not estimates:
            return
        ev, n = self.every, self.published
        for e in estimates:
            try:     # one estimate's failure (a writer that cannot be built) costs no other estimate
                k = self.n_published
                self.n_published = k + 1
                send(self.pub_state, self.w_state.write(e.x_hat, e.stamp_ns))
                n["state"] += 1
                if ev["envelope"] and k % ev["envelope"] == 0 and listened(self.pub_env):
                    send(self.pub_env, self.w_env.write(e.envelope, e.stamp_ns))
                    n["envelope"] += 1
                if e.P is not None and ev["covariance"] and k % ev["covariance"] == 0 and listened(self.pub_cov):
                    send(self.pub_cov, self.w_cov.write(e.P.ravel(), e.stamp_ns))
                    n["covariance"] += 1
                if ev["odometry"] and k % ev["odometry"] == 0 and any(on := listened_each(self.pub_odom)):
                    for pub, m, yes in zip(self.pub_odom, self.w_odom.msgs(e.x_hat, e.stamp_ns, e.P), on):
                        if yes:
                            send(pub, m)
                            n["odometry"] += 1
                if ev["typed"] and k % ev["typed"] == 0:
                    pl = self.pipeline
                    if listened(self.pub_typed[0]):
                        send(self.pub_typed[0], self.w_typed[0].write(e.x_hat, e.stamp_ns, e.P))
                        n["typed"] += 1
                    if listened(self.pub_typed[1]):
                        send(self.pub_typed[1], self.w_typed[1].msg(e.envelope, e.stamp_ns, pl.bound_valid,
                                                                      pl.bound_invalid_why, pl.bound_note))
                        n["typed"] += 1
                if ev["markers"] and k % ev["markers"] == 0 and listened(self.pub_markers):
                    g = e.envelope[-1]      # the guaranteed bound: noise_bound if declared, else exact_bound
                    send(self.pub_markers, self.w_markers.msg(e.x_hat, e.stamp_ns, e.P, g if g >= 0 else None,
                                                                self.body_in_view.get(e.channel)))
                    n["markers"] += 1
            except Exception as err:
                self.pipeline.internal_error("publish", err)
        if self.markers_pending:
            self._create_markers_publisher()
