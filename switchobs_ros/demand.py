"""Outputs on demand: an optional output of the estimator is built and published only while a
subscription is matched to its publisher.

A DDS writer sends a sample only to the readers it has matched (the outputs are volatile: a reader
that joins later never gets what was sent before it), so skipping an output that no reader is
matched to loses nothing that a subscriber could have received. At 32 agents (n = 132) the
per-body odometries, the 139 KB covariance and the typed messages cost several milliseconds per
estimate to build and serialise, and the covariance itself (``P``, n^3 to form from a Kalman
table's stored prior) as much again; none of it is spent while nobody listens.

:class:`Demand` answers two questions:

* ``listened(pub)``: is a subscription matched to ``pub``? rcl's matched count (about 3.7 us a
  call from Python; at 32 agents the outputs ask 15 times per estimate) is kept per publisher:
  a yes for :data:`LISTEN_PERIOD` (0.5 s), a no for :data:`LISTEN_PERIOD_NO` (0.02 s), from the
  last time it was asked, here or by :class:`Demand`'s refresh of the publishers that carry
  ``P`` (every 0.1 s while one is listened; of a kind's publishers, those up to the first listened
  one). So a new subscriber gets the estimates published
  from at most 0.02 s after it is matched (the outputs are volatile: it could never get those
  before it), and after the last subscriber leaves an output is built and published for at most
  0.5 s more, to nobody;
* ``covariance_wanted()``: does any output that carries ``P`` have a subscriber? Asked before
  every estimate reads ``P`` (the node's ``_covariance_due``), of up to 36 publishers at 32
  agents, so the answer is kept: a yes for :attr:`Demand.period` seconds (a subscriber that
  leaves costs at most that long of covariances nobody reads), a no for :attr:`Demand.period_no`
  seconds (for at most that long after the first subscriber to an output carrying ``P`` appears,
  its messages go out without the covariance: the odometry's unknown, the typed estimate's
  empty, as with ``publish_covariance`` false);
* ``kinds``: which of those outputs (``covariance``, ``odometry``, ``typed``, ``markers``) have
  a subscriber, as of the last refresh: the node forms ``P`` only for an estimate one of them
  takes at its decimation (:mod:`switchobs_ros.outputs`).
"""

from __future__ import annotations

import math
import time
import weakref
from collections.abc import Callable, Sequence
from typing import Any

__all__ = ["LISTEN_PERIOD", "LISTEN_PERIOD_NO", "Demand", "listened", "listened_each"]

#: How long :func:`listened` keeps a publisher's yes, and its no (s).
LISTEN_PERIOD = 0.5
LISTEN_PERIOD_NO = 0.02

#: id(publisher) -> (until, answer, a weak reference to the publisher): a plain dict read by the
#: publisher's id (a weak-keyed dict makes a weak reference at every look-up); an entry leaves with
#: its publisher (the reference's callback), and a look-up checks that it is still that publisher's.
_heard: dict[int, tuple[float, bool, weakref.ref]] = {}


def listened(pub: Any, clock: Callable[[], float] = time.monotonic) -> bool:
    """Is a subscription matched to the publisher ``pub`` (None: no such output)? The answer of
    rcl's matched count, kept per publisher for :data:`LISTEN_PERIOD` s (a yes) or
    :data:`LISTEN_PERIOD_NO` s (a no)."""
    return pub is not None and listened_each((pub,), clock)[0]


def listened_each(pubs: Sequence[Any], clock: Callable[[], float] = time.monotonic) -> list[bool]:
    """:func:`listened` of each publisher of ``pubs`` (none None) at one reading of the clock:
    the 33 odometries of 32 agents in one call."""
    now = clock()
    get = _heard.get
    out = []
    for pub in pubs:
        got = get(id(pub))
        out.append(got[1] if got is not None and now < got[0] and got[2]() is pub else _ask(pub, now))
    return out


def _ask(pub: Any, now: float) -> bool:
    """rcl's matched count of ``pub`` now, kept for :func:`listened` (``now`` on its clock)."""
    yes = pub.get_subscription_count() > 0
    key = id(pub)
    got = _heard.get(key)
    ref = got[2] if got is not None and got[2]() is pub else weakref.ref(pub, lambda r, k=key: _forget(k, r))
    _heard[key] = (now + (LISTEN_PERIOD if yes else LISTEN_PERIOD_NO), yes, ref)
    return yes


def _forget(key: int, ref: weakref.ref) -> None:
    """A publisher is gone: its kept answer with it (unless the id already holds another's)."""
    got = _heard.get(key)
    if got is not None and got[2] is ref:
        del _heard[key]


class Demand:
    """Which optional outputs have subscribers (module docstring).

    ``Demand(carriers, period=0.1, period_no=0.02)``: ``carriers()`` returns ``(output, publisher)``
    of the publishers whose messages carry ``P`` (re-read at every refresh: the node may recreate
    its publishers).
    """

    def __init__(self, carriers: Callable[[], Sequence[Any]], period: float = 0.1, period_no: float = 0.02,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self._carriers = carriers
        self.period = float(period)
        self.period_no = float(period_no)
        self._clock = clock
        self._until = -math.inf
        self._wanted = False
        self.kinds: frozenset[str] = frozenset()

    def covariance_wanted(self) -> bool:
        """Whether an output that carries ``P`` has a subscriber (kept for :attr:`period` s, a no
        for :attr:`period_no` s)."""
        now = self._clock()
        if now >= self._until:
            mono = time.monotonic()         # listened()'s clock: the fresh answers kept for it too
            kinds = set()
            for k, p in self._carriers():   # a kind is in once one of its publishers is listened
                if p is not None and k not in kinds and _ask(p, mono):
                    kinds.add(k)
            self.kinds = frozenset(kinds)
            self._wanted = bool(self.kinds)
            self._until = now + (self.period if self._wanted else self.period_no)
        return self._wanted

    def expire(self) -> None:
        """Ask the publishers again at the next :meth:`covariance_wanted` (e.g. after a parameter change)."""
        self._until = -math.inf
