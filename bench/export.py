"""Exports against the read they are built on, on the same 1M-line log, in one run.

The issue's target: exporting 1M entries to Parquet and to MCAP takes at most 2x the time of
reading them with the columnar reader. Per round, interleaved:

(a) read: ``AlogReader.batches()`` of the nine columns the Parquet export reads (the
    baseline; the MCAP export reads seven of them, the source column unsplit);
(b) parquet: ``fleetlog.export.write_parquet`` of the log to a file (tmp dir);
(c) mcap: ``fleetlog.export.export_mcap`` of the log to a file, Foxglove position channels
    included;
(d) mcap package: the ``mcap`` package's own ``Writer`` fed the same messages one by one
    (JSON text made by polars beforehand, not timed), to show why fleetlog writes MCAP
    records itself. Only with ``--mcap-package`` (it is slow).

Ratios are taken within a round against (a), then summarised as median [min-max]. The log
is bench/read_path.py's synthetic mission log (70 % doubles from 8 variables, 30 % strings).

    python bench/export.py                  # 1M lines, 3 rounds
    python bench/export.py -n 300000 --rounds 2 --mcap-package
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from benchlib import loadavg  # noqa: E402
from read_path import write_alog  # noqa: E402

from fleetlog.export import Tally, export_mcap, resolve, write_parquet  # noqa: E402
from fleetlog.storage.columnar import AlogReader  # noqa: E402

COLUMNS = ("time", "offset", "var", "source", "src", "aux", "type", "double", "text")


def run_read(path: Path, out: Path) -> int:
    n = 0
    with AlogReader(path, errors="skip") as reader:
        for batch in reader.batches(COLUMNS):
            n += batch.height
    return n


def run_parquet(path: Path, out: Path) -> int:
    tally = Tally()
    with (out / "x.parquet").open("wb") as f:
        write_parquet(resolve([path]).sources, f, tally)
    return tally.entries


def run_mcap(path: Path, out: Path) -> int:
    tally = Tally()
    with (out / "x.mcap").open("wb") as f:
        export_mcap(resolve([path]).sources, f, tally)
    return tally.entries


def prepare_package(path: Path) -> list[tuple[str, int, bytes]]:
    import polars as pl

    from fleetlog.export.entries import entry_frames
    from fleetlog.export.tomcap import _json, logstart_ns

    source = resolve([path]).sources[0]
    base = logstart_ns(source.logstart or 0.0)
    rows: list[tuple[str, int, bytes]] = []
    for frame in entry_frames(source, Tally(), split=False):
        part = frame.select(
            "variable",
            ((pl.col("offset") * 1e9).round().cast(pl.Int64) + base).alias("t"),
            _json(frame["source"].unique()).cast(pl.Binary).alias("d"),
        )
        rows.extend(part.iter_rows())
    return rows


def run_package(rows: list[tuple[str, int, bytes]], out: Path) -> int:
    from mcap.writer import CompressionType, Writer

    with (out / "p.mcap").open("wb") as f:
        writer = Writer(f, compression=CompressionType.ZSTD)
        writer.start()
        schema = writer.register_schema("fleetlog.MoosValue", "jsonschema", b"{}")
        channels: dict[str, int] = {}
        for var, t, data in rows:
            cid = channels.get(var)
            if cid is None:
                cid = channels[var] = writer.register_channel(f"/v/{var}", "json", schema)
            writer.add_message(cid, log_time=t, data=data, publish_time=t)
        writer.finish()
    return len(rows)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("-n", type=int, default=1_000_000, help="lines in the log")
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--mcap-package", action="store_true", help="also time (d)")
    parser.add_argument(
        "--only", default="", help="comma-separated subset of read,parquet,mcap (read always runs)"
    )
    args = parser.parse_args()
    log = Path(tempfile.gettempdir()) / f"fleetlog-bench-export-{args.n}.alog"
    if not log.exists():
        print(f"writing {log} ({args.n:,} lines)", flush=True)
        write_alog(log, args.n)
    rows = prepare_package(log) if args.mcap_package else None
    runs = {"read": run_read, "parquet": run_parquet, "mcap": run_mcap}
    if args.only:
        keep = {"read", *args.only.split(",")}
        runs = {k: v for k, v in runs.items() if k in keep}
    times: dict[str, list[float]] = {name: [] for name in runs}
    cpus: dict[str, list[float]] = {name: [] for name in runs}
    if rows is not None:
        times["mcap package"] = []
    print(f"load before: {loadavg()}", flush=True)
    with tempfile.TemporaryDirectory(prefix="fleetlog-bench-export-") as tmp:
        out = Path(tmp)
        run_read(log, out)  # not timed: polars' import and the page cache, paid once
        for r in range(args.rounds):
            for name, fn in runs.items():
                began, cpu = time.perf_counter(), time.process_time()
                n = fn(log, out)
                times[name].append(time.perf_counter() - began)
                cpus[name].append(time.process_time() - cpu)
                print(
                    f"round {r + 1} {name:8} {n:,} entries {times[name][-1]:.2f} s"
                    f" (CPU {cpus[name][-1]:.2f} s)",
                    flush=True,
                )
            if rows is not None:
                began = time.perf_counter()
                run_package(rows, out)
                times["mcap package"].append(time.perf_counter() - began)
                print(f"round {r + 1} mcap package {times['mcap package'][-1]:.2f} s", flush=True)
        sizes = {p.name: p.stat().st_size for p in out.iterdir()}
    print(f"load after: {loadavg()}")
    print(
        f"log {log.stat().st_size / 1e6:.1f} MB; outputs "
        + ", ".join(f"{k} {v / 1e6:.1f} MB" for k, v in sorted(sizes.items()))
    )
    print(
        "| | seconds median [min-max] | entries/s | ratio to read, median [min-max] | CPU ratio |"
    )
    print("|---|---|---|---|---|")
    for name, values in times.items():
        ratios = [v / b for v, b in zip(values, times["read"], strict=True)]
        cpu_ratios = [v / b for v, b in zip(cpus.get(name, []), cpus["read"], strict=False)]
        cpu = (
            f"{statistics.median(cpu_ratios):.2f}x [{min(cpu_ratios):.2f}-{max(cpu_ratios):.2f}]"
            if cpu_ratios
            else "-"
        )
        print(
            f"| {name} | {statistics.median(values):.2f} [{min(values):.2f}-{max(values):.2f}]"
            f" | {args.n / statistics.median(values):,.0f}"
            f" | {statistics.median(ratios):.2f}x [{min(ratios):.2f}-{max(ratios):.2f}] | {cpu} |"
        )


if __name__ == "__main__":
    main()
