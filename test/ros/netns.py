"""Several computers on one machine: Linux network namespaces joined by a switch, for the tests
that run publishers and the estimator as they are deployed (each on its own "computer").

:class:`Network` creates one namespace per host and one for the switch (names unique to the
process and the network, at most 15 characters per interface), a veth pair from each host to the
switch, and addresses 10.<k>.0.<i>/24 on the hosts. The switch is a kernel bridge on a clean
network, or, when any link is impaired (:class:`Link`: delay, jitter, loss), a user-space relay
(:func:`relay`, raw packet sockets in the switch namespace: this kernel has no ``netem``) that
forwards every frame to the other ports after the delay of the link it came in on, or drops it.
Everything lives in the namespaces the network created, and deleting them removes it: the
network is deleted on exit, also when the test fails, and at interpreter exit as a last resort.

:meth:`Network.popen` runs a command inside a host with ``ROS_AUTOMATIC_DISCOVERY_RANGE=SUBNET``
(multicast discovery on the switch only), ``FASTDDS_BUILTIN_TRANSPORTS=UDPv4`` (the namespaces
share ``/dev/shm``: Fast DDS's shared-memory transport would bypass the network) and the given
``ROS_DOMAIN_ID``. :func:`unavailable` says why namespaces cannot be made here ('' when they can).
"""

from __future__ import annotations

import atexit
import heapq
import os
import random
import select
import shutil
import socket
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

__all__ = ["Link", "Network", "relay", "unavailable"]

_COUNTER = [0]


@dataclass(frozen=True)
class Link:
    """How a host's link treats the frames it sends: ``delay_ms`` +- ``jitter_ms`` (uniform), and a
    ``loss`` probability per frame."""

    delay_ms: float = 0.0
    jitter_ms: float = 0.0
    loss: float = 0.0

    @property
    def clean(self) -> bool:
        return self.delay_ms == 0 and self.jitter_ms == 0 and self.loss == 0

    def arg(self) -> str:
        return f"{self.delay_ms},{self.jitter_ms},{self.loss}"


def _ip(*args: str, check: bool = True) -> subprocess.CompletedProcess:
    return subprocess.run(["ip", *args], capture_output=True, text=True, check=check, timeout=20)


def unavailable() -> str:
    """'' when this process can create network namespaces, else why not (for a skip)."""
    if shutil.which("ip") is None:
        return "the `ip` command (iproute2) is not installed"
    if os.geteuid() != 0:
        return f"network namespaces need root (id -u is {os.geteuid()})"
    name = f"so{os.getpid() % 100000}probe"
    r = _ip("netns", "add", name, check=False)
    if r.returncode != 0:
        return f"`ip netns add` failed: {r.stderr.strip()}"
    _ip("netns", "del", name, check=False)
    return ""


class Network:
    """Hosts ``names`` on one switch; ``links`` maps a host to its :class:`Link` (default clean).

    Use as a context manager; :meth:`popen` starts a process in a host, :meth:`address` gives a
    host's IP address.
    """

    def __init__(self, names: list[str], links: dict[str, Link] | None = None):
        _COUNTER[0] += 1
        self.tag = f"so{os.getpid() % 100000}{_COUNTER[0]}"         # <= 9 characters
        self.names = list(names)
        self.links = {n: (links or {}).get(n, Link()) for n in names}
        self.ns = {n: f"{self.tag}h{i}" for i, n in enumerate(names)}
        self.switch = f"{self.tag}sw"
        self.subnet = 10 + _COUNTER[0] % 200
        self.procs: list[subprocess.Popen] = []
        self.relay_proc: subprocess.Popen | None = None
        self._made: list[str] = []

    def address(self, name: str) -> str:
        return f"10.{self.subnet}.0.{self.names.index(name) + 1}"

    # ------------------------------------------------------------------ set-up and tear-down
    def __enter__(self) -> Network:
        atexit.register(self.close)
        try:
            self._create()
        except BaseException:
            self.close()
            raise
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def _create(self) -> None:
        for ns in (self.switch, *self.ns.values()):
            _ip("netns", "add", ns)
            self._made.append(ns)
            _ip("-n", ns, "link", "set", "lo", "up")
        bridged = all(link.clean for link in self.links.values())
        if bridged:
            _ip("-n", self.switch, "link", "add", "br0", "type", "bridge")
            _ip("-n", self.switch, "link", "set", "br0", "up")
        ports = []
        for i, (name, ns) in enumerate(self.ns.items()):
            port = f"p{i}"
            _ip("-n", ns, "link", "add", "eth0", "type", "veth", "peer", "name", port, "netns", self.switch)
            _ip("-n", ns, "addr", "add", f"{self.address(name)}/24", "dev", "eth0")
            _ip("-n", ns, "link", "set", "eth0", "multicast", "on", "up")
            _ip("-n", ns, "route", "add", "224.0.0.0/4", "dev", "eth0")
            _ip("-n", self.switch, "link", "set", port, "up")
            if bridged:
                _ip("-n", self.switch, "link", "set", port, "master", "br0")
            ports.append(f"{port}={self.links[name].arg()}")
        if not bridged:
            self.relay_proc = subprocess.Popen(["ip", "netns", "exec", self.switch, sys.executable, __file__, "relay",
                                                *ports], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
            time.sleep(0.3)
            if self.relay_proc.poll() is not None:
                raise RuntimeError(f"the relay did not start: {self.relay_proc.stderr.read().decode()}")

    def close(self) -> None:
        """Stop every process started here and delete the namespaces (idempotent)."""
        for p in [*self.procs, *([self.relay_proc] if self.relay_proc else [])]:
            if p.poll() is None:
                p.terminate()
        deadline = time.monotonic() + 5
        for p in [*self.procs, *([self.relay_proc] if self.relay_proc else [])]:
            try:
                p.wait(timeout=max(0.1, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()
        self.procs, self.relay_proc = [], None
        for ns in reversed(self._made):
            _ip("netns", "del", ns, check=False)
        self._made = []

    # ------------------------------------------------------------------ processes
    def env(self, domain: int, extra: dict | None = None) -> dict:
        env = dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE="SUBNET", FASTDDS_BUILTIN_TRANSPORTS="UDPv4",
                   ROS_DOMAIN_ID=str(domain))
        env.pop("ROS_STATIC_PEERS", None)
        env.update(extra or {})
        return env

    def popen(self, host: str, argv: list[str], domain: int, log: Path, env: dict | None = None) -> subprocess.Popen:
        """Start ``argv`` inside ``host``; its stdout and stderr go to ``log``."""
        fh = open(log, "w")
        p = subprocess.Popen(["ip", "netns", "exec", self.ns[host], *argv], env=self.env(domain, env),
                             stdout=fh, stderr=subprocess.STDOUT, cwd=Path(__file__).resolve().parents[2])
        fh.close()
        self.procs.append(p)
        return p


# ---------------------------------------------------------------------- the impaired switch
def _without_udp_checksum(frame: bytes) -> bytes:
    """An IPv4 UDP frame with its checksum field 0 ("none", RFC 768). A veth leaves the checksum of
    a frame it sends to be filled in later (checksum offload); a frame taken from a packet socket
    and sent again carries that unfinished checksum, which the receiver would drop."""
    if len(frame) < 34 or frame[12:14] != b"\x08\x00" or frame[23] != 17 or \
            int.from_bytes(frame[20:22], "big") & 0x1FFF:      # not UDP, or a later fragment (no UDP header)
        return frame
    at = 14 + (frame[14] & 0x0F) * 4 + 6
    return frame[:at] + b"\x00\x00" + frame[at + 2:] if len(frame) >= at + 2 else frame


def relay(ports: dict[str, tuple[float, float, float]], seed: int = 0) -> None:
    """Forward every frame received on a port to every other port, after the delay of the link it
    came in on (``(delay_ms, jitter_ms, loss)``), or drop it with that link's loss probability. Runs
    until killed (inside the switch namespace: raw packet sockets on the veth ends)."""
    rng = random.Random(seed)
    socks = {}
    for name in ports:
        s = socket.socket(socket.AF_PACKET, socket.SOCK_RAW, socket.htons(0x0003))     # ETH_P_ALL
        s.bind((name, 0x0003))                          # ETH_P_ALL (Python converts to network order)
        s.setblocking(False)
        socks[name] = s
    by_fd = {s.fileno(): n for n, s in socks.items()}
    queue: list[tuple[float, int, str, bytes]] = []
    seq = 0
    while True:
        timeout = max(0.0, queue[0][0] - time.monotonic()) if queue else 1.0
        ready, _, _ = select.select(list(socks.values()), [], [], timeout)
        for s in ready:
            src = by_fd[s.fileno()]
            while True:
                try:
                    frame, addr = s.recvfrom(65535)
                except BlockingIOError:
                    break
                if addr[2] == socket.PACKET_OUTGOING:
                    continue                            # our own transmission on this port
                delay, jitter, loss = ports[src]
                if loss and rng.random() < loss:
                    continue
                frame = _without_udp_checksum(frame)
                at = time.monotonic() + max(0.0, delay + rng.uniform(-jitter, jitter)) * 1e-3
                for dst in socks:
                    if dst != src:
                        seq += 1
                        heapq.heappush(queue, (at, seq, dst, frame))
        now = time.monotonic()
        while queue and queue[0][0] <= now:
            _, _, dst, frame = heapq.heappop(queue)
            try:
                socks[dst].send(frame)
            except OSError as err:          # a port going down as the network is deleted
                print(f"relay: {dst}: {err}", file=sys.stderr, flush=True)


if __name__ == "__main__" and len(sys.argv) > 1 and sys.argv[1] == "relay":
    spec = {}
    for a in sys.argv[2:]:
        name, vals = a.split("=")
        d, j, loss = (float(v) for v in vals.split(","))
        spec[name] = (d, j, loss)
    relay(spec)
