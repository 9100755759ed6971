"""Where an export's CPU goes, stage by stage, against the read (docs/bench.md §10.2).

Each stage of the Parquet and the MCAP export is run on its own, one after the other, on
the inputs the stage before it made (kept in memory), and its CPU time (process time, so
polars' own threads count) taken as the minimum of ``--rounds``. The sum of a format's
stages is what the export costs with no thread waiting on another; the export itself runs
them overlapped on two threads or more, and pays for that too.

    python bench/export_stages.py             # the bench's 1M-line log, 5 rounds
"""

from __future__ import annotations

import argparse
import io
import sys
import tempfile
import time
import zlib
from collections.abc import Callable
from pathlib import Path
from typing import Any

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from benchlib import loadavg  # noqa: E402
from read_path import write_alog  # noqa: E402

from fleetlog.export import Tally, resolve  # noqa: E402
from fleetlog.export.entries import entry_frames  # noqa: E402
from fleetlog.export.foxglove import NAV_VARS, poses  # noqa: E402
from fleetlog.export.mcapchunks import build_chunks  # noqa: E402
from fleetlog.export.parquet import WINDOW, _by_variable, metadata, schema  # noqa: E402
from fleetlog.export.tomcap import _channel_ids, _messages, _timed, logstart_ns  # noqa: E402
from fleetlog.storage.columnar import AlogReader  # noqa: E402

COLUMNS = ("time", "offset", "var", "source", "src", "aux", "type", "double", "text")
_SLICE = 50_000


def main() -> None:
    import numpy as np
    import polars as pl
    import zstandard
    from polars.io.plugins import register_io_source

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("-n", type=int, default=1_000_000, help="lines in the log")
    parser.add_argument("--rounds", type=int, default=5)
    args = parser.parse_args()
    log = Path(tempfile.gettempdir()) / f"fleetlog-bench-export-{args.n}.alog"
    if not log.exists():
        print(f"writing {log} ({args.n:,} lines)", flush=True)
        write_alog(log, args.n)
    source = resolve([log]).sources[0]
    rows: list[tuple[str, float]] = []

    def stage(name: str, fn: Callable[[], Any]) -> Any:
        times = []
        for _ in range(args.rounds):
            began = time.process_time()
            out = fn()
            times.append(time.process_time() - began)
        rows.append((name, min(times)))
        print(f"{name:44} {min(times):.3f} s", flush=True)
        return out

    def read() -> None:
        with AlogReader(log, errors="skip") as reader:
            for _ in reader.batches(COLUMNS):
                pass

    print(f"load before: {loadavg()}", flush=True)
    stage("read (the bench's baseline)", read)

    frames = stage("parquet: read, entry columns", lambda: list(entry_frames(source, Tally())))
    per = max(1, WINDOW // max(1, frames[0].height))
    windows = stage(
        "parquet: order each window by variable",
        lambda: [_by_variable(pl.concat(frames[i : i + per])) for i in range(0, len(frames), per)],
    )
    windows = [
        w.select(
            pl.lit(source.vehicle).alias("vehicle"),
            pl.lit(source.session).alias("session"),
            pl.all(),
        )
        for w in windows
    ]

    def encode() -> None:
        register_io_source(lambda *_: iter(windows), schema=schema(True)).sink_parquet(
            io.BytesIO(),
            compression="zstd",
            statistics=True,
            row_group_size=65_536,
            metadata=metadata([source]),
        )

    stage("parquet: encode, compress (polars' sink)", encode)

    whole = stage(
        "mcap: read, entry columns",
        lambda: list(entry_frames(source, Tally(), split=False)),
    )
    base = logstart_ns(source.logstart or 0.0)
    log_time = (pl.col("offset") * 1e9).round().cast(pl.Int64, strict=False) + base
    names = sorted({n for f in whole for n in f["variable"].unique().to_list()})
    ids = {n: i for i, n in enumerate(names)}
    navs = [ids[n] for n in names if n in NAV_VARS]

    def names_rows() -> list[tuple[pl.DataFrame, pl.DataFrame]]:
        out = []
        for f in whole:
            t = _timed(f.with_columns(log_time=log_time))
            t["variable"].unique().sort().to_list()  # the channels the batch declares
            t = t.with_columns(_channel_ids(ids).alias("channel"))
            nav = (
                t.select("channel", "log_time", "variable", "type", "double")
                .filter(pl.col("channel").is_in(navs))
                .filter(pl.col("type") == "double")
            )
            out.append((t, nav))
        return out

    timed = stage("mcap: log times, channels, position rows", names_rows)
    texts = stage("mcap: JSON text (values)", lambda: [_messages(t) for t, _ in timed])
    chunks = stage(
        "mcap: records, indexes (values)",
        lambda: [c for b in texts for c in build_chunks(b, 0, 1 << 20, np)],
    )
    zstd = zstandard.ZstdCompressor(level=1)
    stage(
        "mcap: zstd, crc32 (values)",
        lambda: [(zstd.compress(c.records), zlib.crc32(c.records)) for c in chunks],
    )
    nav = pl.concat([n.select("log_time", "variable", "double") for _, n in timed])
    nav = nav.with_columns(pl.col("log_time").cast(pl.UInt64))

    def pose_text() -> pl.DataFrame:
        derived = poses(nav)
        return derived.rows.select(
            pl.lit(0, pl.UInt16).alias("channel"), "log_time", derived.data.alias("data")
        )

    posed = stage("mcap: poses (latest values, JSON text)", pose_text)
    pose_chunks = stage(
        "mcap: records, indexes (poses)",
        lambda: [
            c
            for at in range(0, posed.height, _SLICE)
            for c in build_chunks(posed.slice(at, _SLICE), 0, 1 << 20, np)
        ],
    )
    stage(
        "mcap: zstd, crc32 (poses)",
        lambda: [(zstd.compress(c.records), zlib.crc32(c.records)) for c in pose_chunks],
    )
    print(f"load after: {loadavg()}")
    read_cpu = rows[0][1]
    print("| stage | CPU s (min) | × the read |")
    print("|---|---|---|")
    for name, cpu in rows:
        print(f"| {name} | {cpu:.2f} | {cpu / read_cpu:.2f}× |")
    for fmt in ("parquet", "mcap"):
        total = sum(cpu for name, cpu in rows if name.startswith(fmt))
        print(f"| **{fmt}, all stages** | {total:.2f} | **{total / read_cpu:.2f}×** |")


if __name__ == "__main__":
    main()
