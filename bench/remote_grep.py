"""Remote grep throughput against a file fetch of the same session, same vehicle, same run.

The 1M-line alog of ``bench/read_path.py`` (77 MB, written if missing) is the only file of a
session served by ``fleetlog serve`` in a subprocess with polars capped at one thread, as a
recorder caps it (``POLARS_MAX_THREADS=1``; no recorder runs: "recorder idle"). Per round,
interleaved:

* **fetch**: ``fetch_session`` of the session (1 MiB ranges, 8 in flight, sha256, fsync);
* **grep NAV_X**: ``FleetClient.grep`` of one variable (~9 % of the lines), every record read;
* **grep all**: every entry (``limit`` at its maximum), every record read.

Throughput is the alog's bytes over the wall time; ratios per round against the fetch.

    python bench/remote_grep.py                  # 3 rounds
"""

from __future__ import annotations

import argparse
import os
import shutil
import statistics
import tempfile
import time
from pathlib import Path

from fetch_throughput import SESSION, VEHICLE, Served, fetch_round, loadavg, spread
from read_path import write_alog

from fleetlog.shore.client import FleetClient
from fleetlog.transport.session import SessionOptions
from fleetlog.wire.query import MAX_GREP_LIMIT, GrepRequest


def ratio_spread(values: list[float]) -> str:
    return f"{statistics.median(values):.2f} [{min(values):.2f}-{max(values):.2f}]"


def grep_round(endpoint: str, request: GrepRequest) -> tuple[float, int]:
    options = SessionOptions(connect=(endpoint,), multicast_scouting=False)
    with FleetClient.open(options) as client:
        client.require(VEHICLE)
        client.grep_timeout = 600.0
        started = time.perf_counter()
        stream = client.grep(VEHICLE, SESSION, request)
        count = sum(1 for _ in stream)
        seconds = time.perf_counter() - started
    return seconds, count


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--file", type=Path, default=Path("/tmp/fleetlog-bench-read.alog"))
    args = parser.parse_args()
    if not args.file.exists():
        write_alog(args.file, 1_000_000)
    work = Path(tempfile.mkdtemp(prefix="fleetlog-bench-grep-"))
    try:
        session = work / "root" / SESSION
        session.mkdir(parents=True)
        alog = session / f"{SESSION}.alog"
        shutil.copyfile(args.file, alog)
        old = time.time() - 3600
        os.utime(alog, (old, old))
        size = alog.stat().st_size
        os.environ["POLARS_MAX_THREADS"] = "1"
        print(f"{size / 1e6:.0f} MB alog; serve with POLARS_MAX_THREADS=1; load {loadavg()}")
        rates: dict[str, list[float]] = {"fetch": [], "grep NAV_X": [], "grep all": []}
        ratios: dict[str, list[float]] = {"grep NAV_X": [], "grep all": []}
        with Served(work / "root") as endpoint:
            grep_round(endpoint, GrepRequest(variables=("NAV_X",)))  # warm: polars imported
            for round_ in range(args.rounds):
                out = work / f"out{round_}"
                seconds, _ = fetch_round(endpoint, out)
                shutil.rmtree(out, ignore_errors=True)
                rates["fetch"].append(size / seconds / 1e6)
                for name, request in (
                    ("grep NAV_X", GrepRequest(variables=("NAV_X",))),
                    ("grep all", GrepRequest(limit=MAX_GREP_LIMIT)),
                ):
                    seconds, _count = grep_round(endpoint, request)
                    rates[name].append(size / seconds / 1e6)
                    ratios[name].append(rates[name][-1] / rates["fetch"][-1])
        for name, values in rates.items():
            line = f"{name:11s} {spread(values)} MB/s"
            if name in ratios:
                line += f"   x fetch {ratio_spread(ratios[name])}"
            print(line)
        print(f"load after {loadavg()}")
    finally:
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
