"""The heap keeper: it gives freed C heap back after a burst, and only then."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

from fleetlog.storage.heap import HeapKeeper
from fleetlog.storage.procinfo import Statm

MiB = 1 << 20


class Fake:
    """A resident size the test sets, and a trim that brings it down to ``used``."""

    def __init__(self, rss: int) -> None:
        self.rss = rss
        self.used = rss
        self.now = 0.0
        self.trims = 0

    def trim(self) -> bool:
        self.trims += 1
        self.rss = self.used
        return True


def test_trims_after_growth_and_once_more_after_settling() -> None:
    fake = Fake(100 * MiB)
    keeper = HeapKeeper(
        grow=32 * MiB,
        settle=60.0,
        resident=lambda: fake.rss,
        trim=fake.trim,
        clock=lambda: fake.now,
    )
    assert keeper.check() == 0  # the first look only learns where it stands
    fake.rss += 31 * MiB
    assert (keeper.check(), fake.trims) == (0, 0)  # below the threshold: nothing
    fake.rss = 250 * MiB  # a burst freed, but kept by the allocator
    assert (keeper.check(), fake.trims) == (150 * MiB, 1)
    assert (keeper.check(), fake.trims) == (0, 1)  # flat: no trim
    # A trim in the middle of a burst gives little back; what the burst frees later is
    # given back once ``settle`` seconds passed, while the size stays above its lowest.
    fake.used = 200 * MiB
    fake.rss = 240 * MiB
    fake.now = 10.0
    assert (keeper.check(), fake.trims) == (40 * MiB, 2)
    fake.used = 100 * MiB  # freed, but the resident size stays at 200 MiB until a trim
    fake.now = 50.0
    assert (keeper.check(), fake.trims) == (0, 2)
    fake.now = 71.0
    assert (keeper.check(), fake.trims) == (100 * MiB, 3)
    assert keeper.stats == {"trims": 3, "released": 290 * MiB}


_BURST = """
import ctypes, ctypes.util, json
from fleetlog.storage.heap import HeapKeeper, trim_heap
MiB = 1 << 20
libc = ctypes.CDLL(ctypes.util.find_library("c"))
libc.malloc.restype = ctypes.c_void_p
libc.malloc.argtypes = [ctypes.c_size_t]
libc.free.argtypes = [ctypes.c_void_p]
can = trim_heap()
keeper = HeapKeeper(grow=32 * MiB)
keeper.check()
big, pins = [], []
for _ in range(2000):
    block = libc.malloc(60_000)
    ctypes.memset(block, 1, 60_000)
    big.append(block)
    pins.append(libc.malloc(64))
for block in big:
    libc.free(block)
released = keeper.check()
print(json.dumps({"can": can, "released": released, "trims": keeper.stats["trims"]}))
"""


def test_gives_back_what_the_c_heap_keeps() -> None:
    # Real glibc, in a process of its own (no other test's threads or heap): 120 MiB of
    # 60 KB blocks, each pinned by a small block after it so the heap's top cannot shrink,
    # touched, then freed: the allocator keeps them resident until the keeper trims.
    done = subprocess.run(
        [sys.executable, "-c", _BURST], capture_output=True, text=True, timeout=120, check=True
    )
    result = json.loads(done.stdout)
    assert result["can"]
    assert result["trims"] == 1
    assert result["released"] > 64 * MiB, result


def test_the_resident_size_is_read_again_through_one_descriptor() -> None:
    """``/proc/self/statm`` stays open (an idle recorder reads it with cold caches)."""
    statm = Statm()
    first = statm.pages()
    if first is None:
        pytest.skip("no /proc/self/statm here")
    held = bytearray(64 << 20)
    held[::4096] = b"x" * len(range(0, len(held), 4096))  # touched: resident
    grown = statm.pages()
    assert grown is not None
    assert grown - first >= (60 << 20) // os.sysconf("SC_PAGE_SIZE")
    assert len(held) == 64 << 20
    statm.close()
    again = statm.pages()  # opened again
    assert again is not None
    assert abs(again - grown) < (8 << 20) // os.sysconf("SC_PAGE_SIZE")
    statm.close()
