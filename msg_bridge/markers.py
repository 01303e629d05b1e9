"""RViz markers of the estimate: ``visualization_msgs/MarkerArray`` for ``~/markers``.

Per body with a position (:func:`~msg_bridge.convert.bodies`: planar, on a line (y = 0), with or
without velocity), four markers with fixed namespaces and
ids (the body's position ``k`` in ``bodies``), so RViz replaces them at every message:

* ``switchobs/position``, SPHERE: the estimated position (p_x, p_y), coloured :data:`HIGHLIGHT`
  for the body in view and :data:`BODY` for the others;
* ``switchobs/label``, TEXT_VIEW_FACING: the body's name, above the sphere;
* ``switchobs/covariance``, CYLINDER (flat): the 2-sigma ellipse of the (p_x, p_y) block of P;
* ``switchobs/bound``, LINE_STRIP: a circle of radius ``bound`` around the estimated position
  (the guaranteed bound on ``||x - x_hat||``, hence on each body's position error).

The covariance ellipse is a flat CYLINDER (a translucent disc, one marker and no points): with
the eigen-decomposition ``P_pp = V diag(l_1, l_2) V'`` (``l_1 >= l_2``), its semi-axes are
``2 sqrt(l_i)`` (2 sigma), so ``scale.x = 4 sqrt(l_1)`` and ``scale.y = 4 sqrt(l_2)`` (RViz's
cylinder scales are diameters), turned by the yaw ``atan2(v_1y, v_1x)`` of the major axis. The
2x2 eigen-decomposition is presentation, not estimation.

A marker that has nothing to show (no covariance, no valid bound: None, negative, i.e. withdrawn,
or not finite) is sent with action DELETE, so RViz removes what it drew before; the list of
markers is the same at every call (4 per body, in body order).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence

import numpy as np
from geometry_msgs.msg import Point
from std_msgs.msg import ColorRGBA
from visualization_msgs.msg import Marker, MarkerArray

from switchobs_core.numerics.ellipse import covariance_ellipse, covariance_ellipses

from .convert import Body
from .stamps import NS_PER_S
from .validate import BridgeError

__all__ = [
    "BODY",
    "BOUND",
    "CIRCLE_POINTS",
    "HIGHLIGHT",
    "NAMESPACES",
    "MarkersWriter",
    "RawMarkersWriter",
    "ellipse_disc",
    "ellipse_discs",
]

#: Marker namespaces, in the order of each body's markers.
NAMESPACES = ("switchobs/position", "switchobs/label", "switchobs/covariance", "switchobs/bound")
#: Colours (r, g, b, a): a body, the body in view, the bound circle.
BODY = (0.2, 0.45, 1.0, 1.0)
HIGHLIGHT = (1.0, 0.55, 0.0, 1.0)
BOUND = (0.1, 0.8, 0.2, 1.0)
#: Points of the bound circle (the last repeats the first: a closed LINE_STRIP).
CIRCLE_POINTS = 73
_ELLIPSE_ALPHA = 0.35
_THIN = 0.01        # m: height of the flat ellipse disc, width of the bound line


def _color(rgba: Sequence[float], alpha: float | None = None) -> ColorRGBA:
    r, g, b, a = rgba
    return ColorRGBA(r=r, g=g, b=b, a=a if alpha is None else alpha)


class MarkersWriter:
    """The ``~/markers`` MarkerArray, reused: ``w.msg(x, stamp_ns, P=None, bound=None, active_body=None)``.

    ``bodies`` come from :func:`msg_bridge.bodies` of the state labels; ``frame_id`` is the frame
    of the positions (``map``); ``size`` the sphere diameter (m). In ``msg``: ``x`` the state,
    ``P`` its covariance (n x n) or None, ``bound`` a valid guaranteed bound on ``||x - x_hat||``
    or None, ``active_body`` the name of the body in view or None. Raises
    :class:`~msg_bridge.validate.BridgeError` for a body name it does not know.
    """

    def __init__(self, bodies: Sequence[Body], frame_id: str, size: float = 0.25):
        self.bodies = tuple(bodies)
        self._names = {b.name: k for k, b in enumerate(self.bodies)}
        self._unit = np.exp(1j * np.linspace(0.0, 2.0 * math.pi, CIRCLE_POINTS))
        self._body, self._highlight = _color(BODY), _color(HIGHLIGHT)
        self._msg = MarkerArray()
        self._sets: list[tuple[Marker, Marker, Marker, Marker]] = []
        for k, b in enumerate(self.bodies):
            ms = tuple(self._marker(ns, k, frame_id) for ns in NAMESPACES)
            pos, lab, cov, bnd = ms
            pos.type, pos.color = Marker.SPHERE, _color(BODY)
            pos.scale.x = pos.scale.y = pos.scale.z = size
            lab.type, lab.text, lab.color = Marker.TEXT_VIEW_FACING, b.name, _color((1.0, 1.0, 1.0, 1.0))
            lab.scale.z = 0.8 * size
            lab.pose.position.z = 1.2 * size
            cov.type, cov.color = Marker.CYLINDER, _color(BODY, _ELLIPSE_ALPHA)
            cov.scale.z = _THIN
            bnd.type, bnd.color = Marker.LINE_STRIP, _color(BOUND)
            bnd.scale.x = _THIN * 2
            bnd.points = [Point() for _ in range(CIRCLE_POINTS)]
            bnd.pose.orientation.w = 1.0
            self._sets.append(ms)
            self._msg.markers.extend(ms)

    @staticmethod
    def _marker(ns: str, k: int, frame_id: str) -> Marker:
        m = Marker()
        m.header.frame_id = frame_id
        m.ns, m.id = ns, k
        m.pose.orientation.w = 1.0
        return m

    def msg(self, x: np.ndarray, stamp_ns: int, P: np.ndarray | None = None, bound: float | None = None,
            active_body: str | None = None) -> MarkerArray:
        if active_body is not None and active_body not in self._names:
            raise BridgeError(f"active body '{active_body}' is not one of {', '.join(self._names)}")
        sec, nsec = divmod(int(stamp_ns), NS_PER_S)
        draw_bound = bound is not None and math.isfinite(bound) and bound >= 0.0
        for b, (pos, lab, cov, bnd) in zip(self.bodies, self._sets):
            for m in (pos, lab, cov, bnd):
                m.header.stamp.sec, m.header.stamp.nanosec = sec, nsec
            px, py = float(x[b.p_x]), 0.0 if b.p_y is None else float(x[b.p_y])
            pos.pose.position.x = lab.pose.position.x = cov.pose.position.x = px
            pos.pose.position.y = lab.pose.position.y = cov.pose.position.y = py
            pos.color = self._highlight if b.name == active_body else self._body
            pos.action = lab.action = Marker.ADD
            cov.action = self._ellipse(cov, P, b)
            bnd.action = Marker.DELETE
            if draw_bound:
                bnd.action = Marker.ADD
                for p, u in zip(bnd.points, self._unit):
                    p.x, p.y = px + bound * u.real, py + bound * u.imag
        return self._msg

    @staticmethod
    def _ellipse(cov: Marker, P: np.ndarray | None, b: Body) -> int:
        """Fill the 2-sigma ellipse of body ``b``; return its action (DELETE: nothing to show)."""
        ell = ellipse_disc(P, b)
        if ell is None:
            return Marker.DELETE
        cov.scale.x, cov.scale.y, cov.pose.orientation.z, cov.pose.orientation.w = ell
        return Marker.ADD


def ellipse_disc(P: np.ndarray | None, b: Body) -> tuple[float, float, float, float] | None:
    """``(scale.x, scale.y, orientation.z, orientation.w)`` of body ``b``'s 2-sigma ellipse disc
    (module docstring), or None when there is nothing to show (no ``P``, no ellipse)."""
    if P is None:
        return None
    Ppp = np.zeros((2, 2))      # a body on a line: no spread across it
    for a, i in b.pose_pairs:
        for c, j in b.pose_pairs:
            Ppp[a, c] = P[i, j]
    ell = covariance_ellipse(Ppp, sigmas=2.0)
    if ell is None:
        return None
    sx, sy, yaw = ell
    return sx, _THIN if b.p_y is None else sy, math.sin(yaw / 2.0), math.cos(yaw / 2.0)


def ellipse_discs(P: np.ndarray | None, bodies: Sequence[Body]) -> list[tuple[float, float, float, float] | None]:
    """:func:`ellipse_disc` of every body, the same doubles, with one eigen-decomposition call for
    all of them (:func:`~switchobs_core.numerics.ellipse.covariance_ellipses`)."""
    bodies = tuple(bodies)
    if P is None or not bodies:
        return [None] * len(bodies)
    rows, cols, line = _pose_blocks(bodies)
    Ppp = P[rows, cols]
    Ppp[line] = 0.0             # a body on a line: no spread across it
    return [None if ell is None else (ell[0], _THIN if b.p_y is None else ell[1], math.sin(ell[2] / 2.0),
                                      math.cos(ell[2] / 2.0))
            for b, ell in zip(bodies, covariance_ellipses(Ppp, sigmas=2.0))]


@functools.lru_cache(maxsize=16)
def _pose_blocks(bodies: tuple[Body, ...]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(rows, cols, line)``: ``P[rows, cols]`` is every body's 2 x 2 position block, with the
    entries ``line`` (a body on a line: its y row and column) to be set to 0."""
    idx = np.array([[b.p_x, b.p_x if b.p_y is None else b.p_y] for b in bodies], dtype=np.intp)
    line = np.zeros((len(bodies), 2, 2), dtype=bool)
    for k, b in enumerate(bodies):
        if b.p_y is None:
            line[k, 1, :] = line[k, :, 1] = True
    return idx[:, :, None], idx[:, None, :], line


class RawMarkersWriter:
    """:class:`MarkersWriter` as serialised bytes (:mod:`msg_bridge.raw`): ``w.msg(x, stamp_ns,
    P=None, bound=None, active_body=None)``, the same message.

    The marker array's layout does not change from one call to the next (the same markers, the
    circle's points always there, DELETE or ADD), so it is serialised once; every call writes the
    stamps, positions, colours, actions, ellipses and circles into it with a few numpy calls for
    all the bodies (the ellipses in one batch, :func:`ellipse_discs`: the same doubles as
    :class:`MarkersWriter`'s, one body at a time).
    """

    def __init__(self, bodies: Sequence[Body], frame_id: str, size: float = 0.25):
        from .raw import RawMessage

        w = MarkersWriter(bodies, frame_id, size)
        self.bodies, self._names, self._unit = w.bodies, w._names, w._unit
        B = len(self.bodies)
        fields = {}
        for k in range(B):
            for j in range(4):
                i = 4 * k + j
                fields[f"t{i}"] = (f"markers[{i}].header.stamp.sec", "<i4", 2)
                fields[f"a{i}"] = (f"markers[{i}].action", "<i4", 1)
                if j < 3:
                    fields[f"p{i}"] = (f"markers[{i}].pose.position.x", "<f8", 2)
            fields[f"c{k}"] = (f"markers[{4 * k}].color.r", "<f4", 4)
            fields[f"s{k}"] = (f"markers[{4 * k + 2}].scale.x", "<f8", 2)
            fields[f"o{k}"] = (f"markers[{4 * k + 2}].pose.orientation.z", "<f8", 2)
            fields[f"b{k}"] = (f"markers[{4 * k + 3}].points[0].x", "<f8", 3 * CIRCLE_POINTS)
        msg = w.msg(np.zeros(max((i for b in self.bodies for i in b.indices), default=0) + 1), 0)
        for ms in w._sets:                      # a colour object of its own per sphere (the writer shares one)
            ms[0].color = _color(BODY)
        self._raw = r = RawMessage(msg, fields=fields)
        self._raw.f.clear()                     # one view per dtype over the whole message instead
        buf, off = r.buffer, r.offsets
        f8_at = min((o for name, o in off.items() if name[0] in "psob"), default=4) % 8
        self._f8 = np.frombuffer(buf, dtype="<f8", offset=f8_at, count=(len(buf) - f8_at) // 8)
        self._i4 = np.frombuffer(buf, dtype="<i4", count=len(buf) // 4)
        self._f4 = np.frombuffer(buf, dtype="<f4", count=len(buf) // 4)

        def f8(name, extra=0):
            if (off[name] - f8_at) % 8:
                raise ValueError("raw markers: a float64 field off the 8-byte grid")
            return (off[name] - f8_at) // 8 + extra

        def i4(name, extra=0):
            if off[name] % 4:
                raise ValueError("raw markers: an int32 field off the 4-byte grid")
            return off[name] // 4 + extra

        ip = np.intp
        self._sec = np.array([i4(f"t{i}") for i in range(4 * B)], ip)
        self._px = np.array([[f8(f"p{4 * k + j}") for k in range(B)] for j in range(3)], ip)        # (3, B)
        self._color = np.array([[i4(f"c{k}", c) for c in range(4)] for k in range(B)], ip)          # (B, 4)
        self._cov_action = np.array([i4(f"a{4 * k + 2}") for k in range(B)], ip)
        self._bnd_action = np.array([i4(f"a{4 * k + 3}") for k in range(B)], ip)
        self._ell = np.array([[f8(f"s{k}"), f8(f"s{k}", 1), f8(f"o{k}"), f8(f"o{k}", 1)] for k in range(B)], ip)
        self._circle = np.array([[f8(f"b{k}", 3 * q) for q in range(CIRCLE_POINTS)] for k in range(B)], ip)
        self._ix = np.array([b.p_x for b in self.bodies], ip)
        self._iy = np.array([-1 if b.p_y is None else b.p_y for b in self.bodies], ip)   # -1: the 0 appended to x
        self._body = np.array([BODY], dtype="<f4")
        self._highlight = np.array(HIGHLIGHT, dtype="<f4")

    def msg(self, x: np.ndarray, stamp_ns: int, P: np.ndarray | None = None, bound: float | None = None,
            active_body: str | None = None) -> bytes:
        if active_body is not None and active_body not in self._names:
            raise BridgeError(f"active body '{active_body}' is not one of {', '.join(self._names)}")
        f8, i4, f4 = self._f8, self._i4, self._f4
        sec, nsec = divmod(int(stamp_ns), NS_PER_S)
        i4[self._sec] = sec
        i4[self._sec + 1] = nsec
        xz = np.append(np.asarray(x, dtype=float), 0.0)
        px, py = xz[self._ix], xz[self._iy]
        f8[self._px] = px
        f8[self._px + 1] = py
        f4[self._color] = self._body
        if active_body is not None:
            f4[self._color[self._names[active_body]]] = self._highlight
        ells = ellipse_discs(P, self.bodies)
        shown = [k for k, ell in enumerate(ells) if ell is not None]
        i4[self._cov_action] = Marker.DELETE
        if shown:               # every shown ellipse's scale and orientation in one write
            i4[self._cov_action[shown]] = Marker.ADD
            f8[self._ell[shown]] = [ells[k] for k in shown]
        if bound is not None and math.isfinite(bound) and bound >= 0.0:
            i4[self._bnd_action] = Marker.ADD
            f8[self._circle] = px[:, None] + bound * self._unit.real
            f8[self._circle + 1] = py[:, None] + bound * self._unit.imag
        else:
            i4[self._bnd_action] = Marker.DELETE
        return self._raw.bytes()
