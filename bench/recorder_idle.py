"""What an idle recorder costs: CPU-seconds per 10 s with nothing published, beside its baselines.

In each round, at the same time and for the same window (after a warm-up):

* with ``--also TREE``, the same from another source tree (``PYTHONPATH=TREE``: before/after);
* ``fleetlog record`` (default configuration: wildcard logging, plain alog, fsync each second,
  its own PLOGGER_STATUS every 2 s, which it logs);
* a bare zenoh-python subscriber (one FIFO, blocked in ``recv``): what Zenoh itself costs
  a process that waits for samples;
* where ``MOOS_BIN`` names a folder holding ``MOOSDB`` and ``pLogger`` (core-moos, built by
  hand): a real pLogger (AppTick 10, wildcard logging, its status posts logged) and its
  MOOSDB, on a port of their own.

CPU is read from ``/proc/PID/task/*/schedstat`` (nanoseconds on a CPU, every thread of the
process) at the start and the end of the window. The figure is the median over the rounds,
with the minimum and maximum, and the machine's load average beside it (the machine is
shared)::

    MOOS_BIN=/path/to/core-moos/build/bin python bench/recorder_idle.py --seconds 10 --rounds 3
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

from benchlib import Helper, PLogger, RecorderProcess, cpu_ns, free_port, loadavg, spread


def _also(work: Path, also: Path) -> RecorderProcess:
    """The same command from another source tree (a before/after pair in one run)."""
    (work / "also").mkdir()
    return RecorderProcess(work / "also", free_port(), tree=also)


def one_round(
    seconds: float, warmup: float, moos_bin: Path | None, also: Path | None, also_first: bool
) -> dict[str, float]:
    """Start everything, wait ``warmup``, measure CPU over ``seconds``: CPU-s per 10 s each.

    ``also_first``: start the ``--also`` recorder before this tree's. The one started first
    costs ~10 % more in the same window (an A/A pair showed it, docs/bench.md §18), so the
    rounds alternate the order.
    """
    with tempfile.TemporaryDirectory(prefix="fleetlog-idle-") as tmp:
        work = Path(tmp)
        (work / "rec").mkdir()
        other = _also(work, also) if also is not None and also_first else None
        rec = RecorderProcess(work / "rec", free_port())
        if also is not None and other is None:
            other = _also(work, also)
        bare = Helper("counter", ["--listen", f"tcp/127.0.0.1:{free_port()}", "-n", "1000000000"])
        bare.read()
        plogger = None
        if moos_bin is not None:
            (work / "moos").mkdir()
            plogger = PLogger(moos_bin, work / "moos", app_tick=10)
        try:
            time.sleep(warmup)
            pids = {"fleetlog": rec.proc.pid, "bare": bare.proc.pid}
            if other is not None:
                pids["also"] = other.proc.pid
            if plogger is not None:
                pids["pLogger"] = plogger.logger.pid
                pids["MOOSDB"] = plogger.db.pid
            start = {name: cpu_ns(pid) for name, pid in pids.items()}
            began = time.monotonic()
            time.sleep(seconds)
            end = {name: cpu_ns(pid) for name, pid in pids.items()}
            scale = 10.0 / (time.monotonic() - began) / 1e9
            return {name: (end[name] - start[name]) * scale for name in pids}
        finally:
            rec.stop()
            if other is not None:
                other.stop()
            bare.proc.kill()
            bare.proc.wait()
            if plogger is not None:
                plogger.close()


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=10.0, help="measured window per round")
    parser.add_argument("--warmup", type=float, default=3.0, help="seconds before the window")
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument(
        "--also", type=Path, help="a second fleetlog source tree to run beside (e.g. main)"
    )
    args = parser.parse_args()
    folder = os.environ.get("MOOS_BIN", "")
    moos_bin = Path(folder) if folder and (Path(folder) / "pLogger").is_file() else None
    if moos_bin is None:
        print("MOOS_BIN unset (or no pLogger in it): no pLogger baseline", file=sys.stderr)
    rounds = []
    loads = []
    for i in range(args.rounds):
        loads.append(float(loadavg()) if loadavg() != "?" else float("nan"))
        rounds.append(one_round(args.seconds, args.warmup, moos_bin, args.also, i % 2 == 1))
    names = list(rounds[0])
    load = spread(loads, "{:.1f}")
    print(f"idle CPU-s per 10 s, {args.rounds} rounds of {args.seconds:g} s, load {load}")
    for name in names:
        print(f"  {name:<10} {spread([r[name] for r in rounds], '{:.4f}')}")
    if moos_bin is not None:
        both = [r["pLogger"] + r["MOOSDB"] for r in rounds]
        print(f"  {'pLogger+DB':<10} {spread(both, '{:.4f}')}")
        ratio = [r["fleetlog"] / max(r["pLogger"], 1e-9) for r in rounds]
        print(f"fleetlog / pLogger alone: {spread(ratio, '{:.2f}')}x")
    above = [r["fleetlog"] - r["bare"] for r in rounds]
    if args.also is not None:
        ratio = [r["also"] / max(r["fleetlog"], 1e-9) for r in rounds]
        print(f"{args.also} / this tree: {spread(ratio, '{:.1f}')}x")
    print(f"fleetlog - bare subscriber: {spread(above, '{:.4f}')}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
