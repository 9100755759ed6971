"""Snapshot mode at a steady rate: what a snapshot holds, the memory it takes, what holding costs.

The recorder's engine (``fleetlog.recorder.engine.Recorder``, real files) is fed a steady
stream on a simulated clock: ``--rate`` samples a second over ten variables (doubles and
strings) for ``--minutes`` of simulated time, as fast as the CPU runs it. Then a SNAPSHOT is
taken and its session read back, and the script checks that it holds exactly the samples
that arrived in the last ``--seconds`` plus each variable's latest older value, once each,
with their time stamps.

Figures (paired in the same process, so the machine's load affects both alike):

* memory: the process's peak RSS growth over the run against ``SnapshotMemory``, and the real
  bytes per held sample (tracemalloc, on a separate 50,000-sample ring) against what the ring
  counts for it (its estimate must be the larger);
* cost: microseconds per sample held in snapshot mode against per sample recorded as pLogger
  does (the baseline: the same stream written to an alog), and the ratio.

    python bench/snapshot.py                          # 10 min at 10k/s, a 30 s window, 256MB
    python bench/snapshot.py --minutes 2 --memory 64MB  # a bound that evicts
"""

from __future__ import annotations

import argparse
import dataclasses
import gc
import sys
import tempfile
import time
import tracemalloc
from collections.abc import Iterator
from pathlib import Path

from benchlib import loadavg

from fleetlog.moos.keep_settings import SnapshotSettings
from fleetlog.moos.mission import LoggerConfig, parse_mission
from fleetlog.moos.units import parse_size
from fleetlog.recorder.engine import Recorder
from fleetlog.recorder.snapshot import SnapshotRing
from fleetlog.storage.readers import AlogReader
from fleetlog.wire.message import MoosMessage

T0 = 1_800_000_000.0
NAMES = [f"NAV_{i}" for i in range(8)] + ["MODE", "STATE_TEXT"]


def vm(field: str) -> int:
    """A /proc/self/status figure in bytes (VmRSS, VmHWM)."""
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith(field + ":"):
            return int(line.split()[1]) * 1024
    return 0


class Clock:
    def __init__(self) -> None:
        self.t = T0

    def __call__(self) -> float:
        return self.t


def stream(n: int, rate: float) -> Iterator[tuple[float, MoosMessage]]:
    """(arrival, message): sample k of variable k % 10 at T0 + (k + 1) / rate."""
    for k in range(n):
        t = T0 + (k + 1) / rate
        name = NAMES[k % 10]
        value: float | str = f"state {k} ok" if k % 10 >= 8 else float(k)
        yield t, MoosMessage(name, value, t, "iBench", "", "bench")


def config(where: Path, snapshot: SnapshotSettings | None) -> LoggerConfig:
    text = (
        f"ProcessConfig = pLogger\n{{\n  Path = {where}\n  File = B\n  MinFreeDisk = 0\n"
        + "".join(f"  Log = {name} @ 0\n" for name in NAMES)
        + "}\n"
    )
    cfg = parse_mission(text, "bench.moos").logger_config()
    return dataclasses.replace(cfg, snapshot=snapshot)


def run(
    where: Path, n: int, rate: float, snapshot: SnapshotSettings | None
) -> tuple[Recorder, float, float]:
    """Feed ``n`` samples; return the recorder, seconds per sample, and the clock at the end."""
    where.mkdir()
    clock = Clock()
    rec = Recorder(config(where, snapshot), vehicle="bench", publish=lambda m: None, clock=clock)
    rec.start()
    handle = rec.handle
    tick_every = int(rate // 50) or 1  # the drain loop's 20 ms tick
    gc.collect()
    started = time.process_time()
    for k, (t, msg) in enumerate(stream(n, rate)):
        clock.t = t
        handle(msg)
        if k % tick_every == 0:
            rec.tick()
    spent = time.process_time() - started
    return rec, spent / n, clock.t


def check_snapshot(rec: Recorder, clock_t: float, n: int, rate: float, seconds: float) -> str:
    """Take a SNAPSHOT, write it, and check it holds exactly what it must."""
    outcome = rec.snapshot("bench")
    assert outcome.ok, outcome.why
    directory = Path(outcome.extra["directory"])
    while rec.session is not None:
        rec.tick()
    horizon = clock_t - seconds
    window = [k for k in range(n) if T0 + (k + 1) / rate >= horizon]
    older: dict[str, int] = {}
    for k in range(window[0] if window else n):
        older[NAMES[k % 10]] = k
    expected = sorted(older.values()) + window
    got: list[int] = []
    alog = directory / f"{directory.name}.alog"
    with AlogReader(alog, errors="raise") as reader:
        for record in reader.records():
            value = record.entry.value
            k = int(value) if isinstance(value, float) else int(str(value).split()[1])
            assert abs(record.time - (T0 + (k + 1) / rate)) < 1e-3, (k, record.time)
            got.append(k)
    assert got == expected, f"the snapshot holds {len(got)} samples, {len(expected)} expected"
    return f"{len(window):,} window samples + {len(older)} older values, exactly, stamps kept"


def bytes_per_held(samples: int = 50_000) -> tuple[float, float]:
    """Real bytes per held sample (tracemalloc) and what the ring counts for it."""
    ring = SnapshotRing(seconds=1e9, memory=1 << 40)
    msgs = stream(samples, 10_000.0)
    gc.collect()
    tracemalloc.start()
    before = tracemalloc.get_traced_memory()[0]
    for t, msg in msgs:
        # a fresh message and strings per sample, as the decoder makes them
        ring.add(t, t, MoosMessage("".join(msg.name), msg.value, t, "".join("iBench"), "", "bench"))
    real = tracemalloc.get_traced_memory()[0] - before
    tracemalloc.stop()
    return real / samples, ring.bytes / samples


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--minutes", type=float, default=10.0, help="simulated minutes")
    parser.add_argument("--rate", type=float, default=10_000.0, help="samples a second")
    parser.add_argument("--seconds", type=float, default=30.0, help="SnapshotSeconds")
    parser.add_argument("--memory", default="256MB", help="SnapshotMemory")
    parser.add_argument("--after", type=float, default=0.0, help="SnapshotAfter")
    args = parser.parse_args()
    n = int(args.minutes * 60 * args.rate)
    memory = parse_size(args.memory)
    settings = SnapshotSettings(args.seconds, memory, args.after)
    print(f"load {loadavg()} (1-minute average; 2 shared cores)", flush=True)
    with tempfile.TemporaryDirectory(prefix="fleetlog-bench-") as tmp:
        where = Path(tmp)
        gc.collect()
        base_rss = vm("VmRSS")
        rec, per_held, clock_t = run(where / "snap", n, args.rate, settings)
        peak = vm("VmHWM") - base_rss
        status = rec.status()["snapshot"]
        print(
            f"snapshot mode: {n:,} samples ({args.minutes:g} min at {args.rate:,.0f}/s), "
            f"{per_held * 1e6:.2f} µs each; ring {status['samples']:,} samples, "
            f"{status['bytes'] / 1e6:,.1f} MB counted of {memory / 1e6:,.0f} MB, "
            f"span {status['span']:.2f} s, evicted {status['evicted']:,}",
            flush=True,
        )
        print(
            f"peak RSS growth {peak / 1e6:,.1f} MB = {peak / memory:.2f} x SnapshotMemory",
            flush=True,
        )
        if status["evicted"] == 0:
            print("check: " + check_snapshot(rec, clock_t, n, args.rate, args.seconds), flush=True)
        rec.stop()
        del rec
        gc.collect()
        base, per_logged, _ = run(where / "plain", n, args.rate, None)
        base.stop()
        print(
            f"baseline (recording as pLogger, same stream): {per_logged * 1e6:.2f} µs each; "
            f"snapshot/baseline {per_held / per_logged:.2f}",
            flush=True,
        )
    real, counted = bytes_per_held()
    print(
        f"held sample: {real:,.0f} B real (tracemalloc), {counted:,.0f} B counted "
        f"(estimate/real {counted / real:.2f})",
        flush=True,
    )
    print(f"load {loadavg()} at the end", flush=True)


if __name__ == "__main__":
    sys.exit(main())
