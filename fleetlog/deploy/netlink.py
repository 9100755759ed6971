"""Network namespaces joined by an emulated radio link: delay, loss, a bandwidth cap, cuts.

The demo and the link tests put each vehicle and the shore in network namespaces of their
own, joined point to point by a :class:`RadioLink`. The link is a pair of TUN devices, one
in each namespace, whose packets a thread of this process carries across: it drops a share
of them (loss), holds each back (delay), lets them out no faster than the rate (a token
bucket with a bounded queue, as ``tc tbf``), and drops everything while the link is cut.
It is what ``tc netem`` with ``tbf`` does, in user space: netem is not built into every
kernel (not into the one these tests were written on), TUN devices are. Real kernel TCP
stacks run on both ends, so retransmission, congestion control and timeouts are the real
ones.

Needs root (CAP_NET_ADMIN) and the ``ip`` command; :func:`namespaces_possible` says whether
this machine can.
"""

from __future__ import annotations

import contextlib
import fcntl
import os
import random
import select
import shutil
import struct
import subprocess
import threading
import time
from collections import deque
from dataclasses import dataclass

from fleetlog.errors import FleetlogError

__all__ = ["LinkShape", "Namespace", "RadioLink", "namespaces_possible"]

_TUNSETIFF = 0x400454CA
_IFF_TUN = 0x0001
_IFF_NO_PI = 0x1000


class NetnsError(FleetlogError):
    """A network namespace or link could not be set up."""


def _ip(*args: str) -> None:
    done = subprocess.run(["ip", *args], capture_output=True, text=True, timeout=30, check=False)
    if done.returncode != 0:
        msg = f"ip {' '.join(args)} failed: {done.stderr.strip()}"
        raise NetnsError(msg)


def namespaces_possible() -> str | None:
    """None if this machine can make namespaces and TUN links, else why not."""
    if shutil.which("ip") is None:
        return "the ip command (iproute2) is not installed"
    if os.geteuid() != 0:
        return "network namespaces need root (CAP_NET_ADMIN)"
    if not os.path.exists("/dev/net/tun"):
        return "/dev/net/tun is missing"
    name = f"fltry{os.getpid() % 100000}"
    try:
        _ip("netns", "add", name)
    except NetnsError as err:
        return str(err)
    with contextlib.suppress(NetnsError):
        _ip("netns", "del", name)
    return None


class Namespace:
    """A network namespace with its loopback up, deleted by :meth:`close`."""

    def __init__(self, name: str) -> None:
        self.name = name
        _ip("netns", "add", name)
        try:
            self.run_ip("link", "set", "lo", "up")
        except NetnsError:
            self.close()
            raise

    def run_ip(self, *args: str) -> None:
        """Run ``ip ARGS`` in the namespace."""
        _ip("-n", self.name, *args)

    def command(self, argv: list[str]) -> list[str]:
        """``argv`` run inside the namespace."""
        return ["ip", "netns", "exec", self.name, *argv]

    def close(self) -> None:
        """Delete the namespace (the processes in it must be gone)."""
        with contextlib.suppress(NetnsError):
            _ip("netns", "del", self.name)


@dataclass
class LinkShape:
    """What the link does to packets (each direction alike).

    Attributes:
        delay: seconds each packet is held back, each way.
        loss: the share of packets dropped, each way (0-1).
        rate: bits per second, or 0 for no cap.
        queue: seconds of packets the bottleneck holds before it drops (tbf's latency).
        cut: drop everything.
    """

    delay: float = 0.0
    loss: float = 0.0
    rate: float = 0.0
    queue: float = 0.1
    cut: bool = False


class _Direction:
    def __init__(self, out_fd: int, shape: LinkShape) -> None:
        self.out_fd = out_fd
        self.shape = shape
        self.pending: deque[tuple[float, bytes]] = deque()
        self.busy_until = 0.0
        self.sent = 0
        self.sent_bytes = 0
        self.dropped = 0


class RadioLink:
    """A point-to-point link between two namespaces, carried and shaped by this process.

    Args:
        a: one end's namespace; ``addr_a`` its address on the link.
        b: the other end's namespace; ``addr_b`` its address.
        shape: how the link behaves from a to b (as netem and tbf on a's interface) and, unless
            ``back`` is given, from b to a too; change either at any time with :meth:`set`.
        back: how it behaves from b to a.
        seed: for the loss pattern (reproducible runs).
    """

    def __init__(
        self,
        a: Namespace,
        addr_a: str,
        b: Namespace,
        addr_b: str,
        shape: LinkShape | None = None,
        back: LinkShape | None = None,
        seed: int = 1,
    ) -> None:
        self.shape = shape or LinkShape()
        self.back = back or LinkShape(**vars(self.shape))
        self._random = random.Random(seed)
        self._lock = threading.Lock()
        self._stop = threading.Event()
        tag = f"{os.getpid() % 10000}{id(self) % 1000}"
        self._fds: list[int] = []
        try:
            fd_a = self._tun(f"fla{tag}", a, addr_a, addr_b)
            fd_b = self._tun(f"flb{tag}", b, addr_b, addr_a)
        except BaseException:
            self._close_fds()
            raise
        # packets read from a's device go out of b's, and the other way round
        self._dirs = {fd_a: _Direction(fd_b, self.shape), fd_b: _Direction(fd_a, self.back)}
        self._thread = threading.Thread(target=self._run, name="fleetlog-radio", daemon=True)
        self._thread.start()

    def _tun(self, name: str, ns: Namespace, local: str, peer: str) -> int:
        fd = os.open("/dev/net/tun", os.O_RDWR | os.O_NONBLOCK)
        self._fds.append(fd)
        fcntl.ioctl(fd, _TUNSETIFF, struct.pack("16sH", name.encode(), _IFF_TUN | _IFF_NO_PI))
        # The device stays ours (the descriptor) once moved into its namespace.
        _ip("link", "set", name, "netns", ns.name)
        ns.run_ip("addr", "add", local, "peer", peer, "dev", name)
        ns.run_ip("link", "set", name, "mtu", "1500", "up")
        return fd

    def set(self, way: str = "both", **changes: float | bool) -> None:
        """Change the link's shape (``delay=``, ``loss=``, ``rate=``, ``queue=``, ``cut=``).

        ``way``: ``both``, ``out`` (a to b) or ``back`` (b to a).
        """
        shapes = {"both": (self.shape, self.back), "out": (self.shape,), "back": (self.back,)}
        with self._lock:
            for shape in shapes[way]:
                for key, value in changes.items():
                    if not hasattr(shape, key):
                        msg = f"a link has no {key!r}"
                        raise NetnsError(msg)
                    setattr(shape, key, value)

    def cut(self) -> None:
        """Drop every packet, both ways, until :meth:`restore`."""
        self.set(cut=True)

    def restore(self) -> None:
        """End a cut."""
        self.set(cut=False)

    @property
    def bytes_carried(self) -> int:
        """Bytes carried, both ways (IP packets)."""
        return sum(d.sent_bytes for d in self._dirs.values())

    @property
    def counters(self) -> tuple[int, int]:
        """Packets carried and dropped, both ways."""
        return (
            sum(d.sent for d in self._dirs.values()),
            sum(d.dropped for d in self._dirs.values()),
        )

    def _admit(self, direction: _Direction, packet: bytes, now: float) -> None:
        with self._lock:
            shape = LinkShape(**vars(direction.shape))
        if shape.cut or (shape.loss and self._random.random() < shape.loss):
            direction.dropped += 1
            return
        start = max(now, direction.busy_until)
        if shape.rate:
            if start - now > shape.queue:
                direction.dropped += 1  # the bottleneck's queue is full: tail drop
                return
            direction.busy_until = start + len(packet) * 8 / shape.rate
        else:
            direction.busy_until = start
        direction.pending.append((direction.busy_until + shape.delay, packet))

    def _run(self) -> None:
        fds = list(self._dirs)
        while not self._stop.is_set():
            now = time.monotonic()
            wait = 0.05
            for direction in self._dirs.values():
                while direction.pending and direction.pending[0][0] <= now:
                    _, packet = direction.pending.popleft()
                    with contextlib.suppress(OSError):
                        os.write(direction.out_fd, packet)
                        direction.sent += 1
                        direction.sent_bytes += len(packet)
                if direction.pending:
                    wait = min(wait, direction.pending[0][0] - now)
            try:
                ready, _, _ = select.select(fds, [], [], max(wait, 0.0))
            except (OSError, ValueError):
                return
            now = time.monotonic()
            for fd in ready:
                for _ in range(64):
                    try:
                        packet = os.read(fd, 65536)
                    except (BlockingIOError, OSError):
                        break
                    self._admit(self._dirs[fd], packet, now)

    def _close_fds(self) -> None:
        for fd in self._fds:
            with contextlib.suppress(OSError):
                os.close(fd)
        self._fds.clear()

    def close(self) -> None:
        """Stop carrying packets and remove the devices."""
        self._stop.set()
        if hasattr(self, "_thread"):
            self._thread.join(2)
        self._close_fds()
