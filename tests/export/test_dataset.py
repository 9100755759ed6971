"""The fleet dataset: a shore archive as hive-partitioned Parquet, grown without rewriting."""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import polars as pl
import pyarrow.dataset as pads
from export.support import IVP, RUN_A1, RUN_A2, THEMOOS, copy_session, expected
from helpers import run_cli

import fleetlog
from fleetlog.export import export_dataset, resolve
from fleetlog.export.dataset import FILE_NAME, dataset_files, partition_dir


def archive(tmp_path: Path) -> Path:
    """ARCHIVE/VEHICLE/SESSION/ as fetch --all and the collector lay it out."""
    root = tmp_path / "archive"
    copy_session(IVP, root / "alpha" / IVP.name)
    copy_session(RUN_A1, root / "alpha" / RUN_A1.name)
    copy_session(THEMOOS, root / "bravo" / THEMOOS.name)
    return root


def count(session: Path) -> int:
    return len(expected(next(p for p in session.iterdir() if ".alog" in p.name)))


def snapshot(dataset: Path) -> dict[Path, tuple[int, int, bytes]]:
    return {
        p: (p.stat().st_ino, p.stat().st_mtime_ns, p.read_bytes()) for p in dataset_files(dataset)
    }


def test_dataset_counts_per_vehicle_and_grows_without_rewriting(tmp_path: Path) -> None:
    root = archive(tmp_path)
    dataset = tmp_path / "dataset"
    done = run_cli("export", str(root), "-o", f"{dataset}/")
    assert done.returncode == 0, done.stderr
    assert "3 session(s) added" in done.stderr

    def per_vehicle() -> dict[str, int]:
        lazy = pl.scan_parquet(f"{dataset}/**/*.parquet", hive_partitioning=True)
        return dict(lazy.group_by("vehicle").len().collect().iter_rows())

    assert per_vehicle() == {"alpha": count(IVP) + count(RUN_A1), "bravo": count(THEMOOS)}
    # a directory scan works too: nothing but the sessions' files is in the tree
    assert pl.scan_parquet(dataset, hive_partitioning=True).select(pl.len()).collect().item() == (
        count(IVP) + count(RUN_A1) + count(THEMOOS)
    )
    # and pyarrow's dataset reader sees the same table
    table = pads.dataset(dataset, format="parquet", partitioning="hive").to_table()
    assert table.num_rows == count(IVP) + count(RUN_A1) + count(THEMOOS)

    before = snapshot(dataset)
    copy_session(RUN_A2, root / "bravo" / RUN_A2.name)
    again = run_cli("export", str(root), "-o", str(dataset))
    assert again.returncode == 0, again.stderr
    assert "1 session(s) added" in again.stderr
    assert "3 already there" in again.stderr
    after = snapshot(dataset)
    assert set(after) - set(before) == {partition_dir(dataset, "bravo", RUN_A2.name) / FILE_NAME}
    for path, state in before.items():
        assert after[path] == state  # same inode, same modification time, same bytes
    assert per_vehicle() == {
        "alpha": count(IVP) + count(RUN_A1),
        "bravo": count(THEMOOS) + count(RUN_A2),
    }
    # fleetlog.open reads the dataset as one table in time order
    frame = fleetlog.open(dataset)
    assert frame.height == sum(per_vehicle().values())
    assert frame["time"].is_sorted()
    assert set(frame["session"].unique()) == {IVP.name, RUN_A1.name, THEMOOS.name, RUN_A2.name}


def test_a_session_still_being_fetched_waits_for_the_next_run(tmp_path: Path) -> None:
    root = archive(tmp_path)
    part = root / "bravo" / "LATE"
    part.mkdir(parents=True)
    source = next(RUN_A2.glob("*.alog"))
    shutil.copy(source, part / "LATE.alog.part")
    dataset = tmp_path / "dataset"
    done = run_cli("export", str(root), "-o", f"{dataset}/")
    assert done.returncode == 1
    assert "still being fetched" in done.stderr
    assert "LATE" in done.stderr
    assert len(dataset_files(dataset)) == 3
    os.rename(part / "LATE.alog.part", part / "LATE.alog")
    again = run_cli("export", str(root), "-o", f"{dataset}/")
    assert again.returncode == 0, again.stderr
    assert (partition_dir(dataset, "bravo", "LATE") / FILE_NAME).is_file()


def test_a_changed_session_is_reported_not_rewritten(tmp_path: Path) -> None:
    root = archive(tmp_path)
    dataset = tmp_path / "dataset"
    export_dataset(resolve([root]), dataset)
    target = partition_dir(dataset, "bravo", THEMOOS.name) / FILE_NAME
    state = target.read_bytes()
    alog = next((root / "bravo" / THEMOOS.name).glob("*.alog"))
    with alog.open("ab") as f:
        f.write(b"99.00000        NAV_X                pNav            1.00000      \n")
    result = export_dataset(resolve([root]), dataset)
    assert result.changed == [("bravo", THEMOOS.name)]
    assert not result.written
    assert target.read_bytes() == state


def test_partition_values_are_escaped_and_decoded(tmp_path: Path) -> None:
    root = tmp_path / "archive"
    odd = "b ravo=x%é"
    copy_session(THEMOOS, root / odd / "S=1/2".replace("/", "_"))
    dataset = tmp_path / "dataset"
    export_dataset(resolve([root]), dataset)
    frame = pl.scan_parquet(f"{dataset}/**/*.parquet", hive_partitioning=True).collect()
    assert set(frame["vehicle"].unique()) == {odd}
    assert set(frame["session"].unique()) == {"S=1_2"}
    assert [p.parent.parent.name for p in dataset_files(dataset)] == [
        "vehicle=b%20ravo%3Dx%25%C3%A9"
    ]


def test_an_interrupted_export_leaves_no_partial_file(tmp_path: Path) -> None:
    root = archive(tmp_path)
    bad = root / "bravo" / "BROKEN"
    bad.mkdir()
    # a compressed log whose data is corrupt: the strict policy stops the export there
    (bad / "BROKEN.alog.gz").write_bytes(b"\x1f\x8b\x08\x00" + b"\x00" * 40)
    dataset = tmp_path / "dataset"
    done = run_cli("export", str(root), "-o", f"{dataset}/", "--strict")
    assert done.returncode == 1
    assert "Traceback" not in done.stderr
    files = sorted(p.name for p in dataset.rglob("*") if p.is_file())
    assert all(name == FILE_NAME for name in files)
    assert not (partition_dir(dataset, "bravo", "BROKEN") / FILE_NAME).exists()
