"""What closing compressed units more often costs in size (issue 11: a crash loses < 1 s).

Writes the same alog-like lines (4 doubles and a status string, as a vehicle posts them)
through fleetlog's ZstdStream and GzipStream, flushed as the recorder flushes (every 5 ms of
simulated time), with units closed every 1, 0.5 and 0.25 s, at 1,000, 10,000 and 50,000
lines per simulated second; prints each file's size relative to the 1 s unit. No Zenoh.

    python bench/compressed_units.py
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

from fleetlog.moos.alog import LineFormatter
from fleetlog.storage import streams


def write(kind: str, path: Path, rate: float, seconds: float, interval: float) -> int:
    streams.COMPRESSED_FLUSH_INTERVAL = interval
    stream = streams.ZstdStream(path) if kind == "zstd" else streams.GzipStream(path)
    fmt = LineFormatter()
    n = int(rate * seconds)
    names = ("NAV_X", "NAV_Y", "NAV_HEADING", "NAV_SPEED", "PHELMIVP_STATUS")
    next_flush = 0.0
    for i in range(n):
        t = i / rate
        name = names[i % 5]
        if name == "PHELMIVP_STATUS":
            stream.write(fmt.string(t, name, "pHelmIvP", f"mode=SURVEY,iter={i},bhvs=3"))
        else:
            stream.write(fmt.double(t, name, "uSimMarine", 100.0 + (i % 977) * 0.137))
        if t >= next_flush:
            stream.flush(t)
            next_flush = t + 0.005
    stream.close()
    return path.stat().st_size


def main() -> int:
    print("| stream | lines/s | unit 1 s | unit 0.5 s | unit 0.25 s |")
    print("|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as tmp:
        for kind in ("zstd", "gzip"):
            for rate in (1_000.0, 10_000.0, 50_000.0):
                seconds = max(200_000 / rate, 20.0)
                sizes = [
                    write(kind, Path(tmp) / f"{kind}{rate}{i}", rate, seconds, i)
                    for i in (1.0, 0.5, 0.25)
                ]
                base = sizes[0]
                cells = " | ".join(
                    f"{s / base:.3f}× ({s / seconds / 1024:.1f} KiB/s)" for s in sizes
                )
                print(f"| {kind} | {rate:,.0f} | {cells} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
