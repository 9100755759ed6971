"""A radio link between two network namespaces: a bandwidth cap, a delay, a bounded queue.

``tc netem`` is not built into every kernel (not into the one this was written on), so the
link is a pair of TUN devices, one in each namespace, whose packets a thread of this process
carries across: each direction sends no faster than ``rate`` (a packet departs when the one
before it has been serialised), holds each packet ``delay`` seconds after it departs, drops
what does not fit in a queue of ``queue`` bytes (a radio modem's buffer), and drops
everything while the link is cut. The kernels' TCP stacks run on both ends, so congestion
control, retransmission and timeouts are the real ones.

Needs root (CAP_NET_ADMIN), ``ip`` and ``/dev/net/tun``; :func:`radio_unavailable` says why not.
"""

from __future__ import annotations

import contextlib
import fcntl
import heapq
import os
import select
import shutil
import struct
import subprocess
import threading
import time
from collections import deque

__all__ = ["RadioLink", "radio_unavailable"]

_TUNSETIFF = 0x400454CA
_IFF_TUN = 0x0001
_IFF_NO_PI = 0x1000


def _ip(*args: str) -> None:
    done = subprocess.run(["ip", *args], capture_output=True, text=True, check=False)
    if done.returncode != 0:
        msg = f"ip {' '.join(args)}: {done.stderr.strip()}"
        raise RuntimeError(msg)


def radio_unavailable() -> str | None:
    """Why a radio link cannot be made here, or None."""
    if shutil.which("ip") is None:
        return "the ip command is not installed"
    if os.geteuid() != 0:
        return "namespaces and TUN devices need root"
    if not os.path.exists("/dev/net/tun"):
        return "/dev/net/tun is missing"
    return None


class _Direction:
    def __init__(self, out_fd: int) -> None:
        self.out_fd = out_fd
        self.last_departure = 0.0
        self.queued: deque[tuple[float, int]] = deque()  # (departure, bytes) not yet sent
        self.dropped = 0
        self.carried = 0


class RadioLink:
    """Joins namespace ``a`` (``addr_a``) and ``b`` (``addr_b``) by an emulated radio.

    Args:
        a: a namespace (existing).
        b: the other namespace.
        addr_a: the address of ``a``'s end.
        addr_b: the address of ``b``'s end.
        rate: bits per second, each direction.
        delay: seconds each packet takes after it has been sent, each direction.
        queue: bytes each direction may hold waiting to be sent; more are dropped.
        name: a prefix for the TUN devices (unique on the machine).
    """

    def __init__(
        self,
        a: str,
        b: str,
        addr_a: str,
        addr_b: str,
        *,
        rate: float = 1e6,
        delay: float = 0.2,
        queue: int = 100_000,
        name: str = "flr",
    ) -> None:
        self.rate = rate
        self.delay = delay
        self.queue = queue
        self.cut = False
        self._fds: list[int] = []
        try:
            fd_a = self._tun(f"{name}a", a, addr_a, addr_b)
            fd_b = self._tun(f"{name}b", b, addr_b, addr_a)
        except BaseException:
            self._close_fds()
            raise
        self._ways = {fd_a: _Direction(fd_b), fd_b: _Direction(fd_a)}
        self._heap: list[tuple[float, int, int, bytes]] = []  # (release, seq, out fd, packet)
        self._seq = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="radio-link", daemon=True)
        self._thread.start()

    def _tun(self, dev: str, ns: str, local: str, peer: str) -> int:
        fd = os.open("/dev/net/tun", os.O_RDWR | os.O_CLOEXEC)
        self._fds.append(fd)
        fcntl.ioctl(fd, _TUNSETIFF, struct.pack("16sH", dev.encode(), _IFF_TUN | _IFF_NO_PI))
        os.set_blocking(fd, False)
        _ip("link", "set", dev, "netns", ns)
        _ip("-n", ns, "addr", "add", local, "peer", peer, "dev", dev)
        _ip("-n", ns, "link", "set", dev, "up")
        return fd

    def _admit(self, way: _Direction, packet: bytes, now: float) -> None:
        if self.cut:
            way.dropped += 1
            return
        while way.queued and way.queued[0][0] <= now:
            way.queued.popleft()
        if sum(n for _, n in way.queued) + len(packet) > self.queue:
            way.dropped += 1  # the modem's buffer is full
            return
        departure = max(now, way.last_departure) + len(packet) * 8 / self.rate
        way.last_departure = departure
        way.queued.append((departure, len(packet)))
        self._seq += 1
        heapq.heappush(self._heap, (departure + self.delay, self._seq, way.out_fd, packet))

    def _run(self) -> None:
        fds = list(self._ways)
        while not self._stop.is_set():
            now = time.monotonic()
            while self._heap and self._heap[0][0] <= now:
                _, _, out_fd, packet = heapq.heappop(self._heap)
                with contextlib.suppress(OSError):
                    os.write(out_fd, packet)
                self._ways[fds[0] if out_fd == fds[1] else fds[1]].carried += len(packet)
            wait = min(0.05, self._heap[0][0] - now) if self._heap else 0.05
            try:
                ready, _, _ = select.select(fds, [], [], max(0.0, wait))
            except OSError:
                return  # closed
            now = time.monotonic()
            for fd in ready:
                while True:
                    try:
                        packet = os.read(fd, 65536)
                    except (BlockingIOError, OSError):
                        break
                    if not packet:
                        break
                    self._admit(self._ways[fd], packet, now)

    def set_cut(self, cut: bool) -> None:
        """Cut the link (every packet dropped) or restore it."""
        self.cut = cut

    def counters(self) -> dict[str, int]:
        """Bytes carried and packets dropped, both directions together."""
        ways = self._ways.values()
        return {
            "carried": sum(w.carried for w in ways),
            "dropped": sum(w.dropped for w in ways),
        }

    def _close_fds(self) -> None:
        for fd in self._fds:
            with contextlib.suppress(OSError):
                os.close(fd)
        self._fds.clear()

    def close(self) -> None:
        """Stop carrying packets; the TUN devices vanish with their descriptors."""
        self._stop.set()
        self._thread.join(5)
        self._close_fds()
