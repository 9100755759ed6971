"""The shore's free-space reserve, against the real file system of the test's directory."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from fleetlog.errors import StorageError
from fleetlog.storage.reserve import DiskReserve


class _Clock:
    def __init__(self) -> None:
        self.t = 0.0

    def __call__(self) -> float:
        return self.t


def test_a_reserve_above_the_free_space_refuses(tmp_path: Path) -> None:
    free = shutil.disk_usage(tmp_path).free
    reserve = DiskReserve(tmp_path / "not" / "yet", free + (1 << 30))  # its parent is looked at
    with pytest.raises(StorageError, match=r"kept free \(--min-free-disk\)"):
        reserve.check(1, "S/x.alog")
    DiskReserve(tmp_path, 0).check(1 << 60)  # 0: no check


def test_writes_count_between_looks(tmp_path: Path) -> None:
    free = shutil.disk_usage(tmp_path).free
    clock = _Clock()
    reserve = DiskReserve(tmp_path, free - (8 << 20), clock)  # 8 MiB above the reserve
    reserve.check(3 << 20)
    reserve.check(3 << 20)  # 6 MiB written since the look: still within
    with pytest.raises(StorageError, match="free"):
        reserve.check(3 << 20)  # 9 MiB: over, though the file system was not looked at again
    asked = DiskReserve(tmp_path, free - (8 << 20), clock)
    for _ in range(3):
        asked.check(6 << 20, writing=False)  # asking ahead of a transfer writes nothing
    asked.check(6 << 20)


def test_a_file_larger_than_the_disk_is_refused_whole(tmp_path: Path) -> None:
    # A vehicle's listing is a peer's word: a petabyte file is refused before the first range.
    with pytest.raises(StorageError, match=r"more for S/x\.alog"):
        DiskReserve(tmp_path, 1 << 20).check(10**15, "S/x.alog")
