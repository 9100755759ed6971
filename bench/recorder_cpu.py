"""CPU per message: the recorder against a real pLogger and its MOOSDB, for the same traffic.

In each round, one after the other:

* a bare zenoh-python subscriber (one FIFO, ``try_recv() or recv()``, counting only) fed the
  same traffic by the same publisher: Zenoh's own cost per message, which any Zenoh-based
  recorder pays;
* ``fleetlog record`` (default configuration) while a publisher process (fleetlog's
  ``MoosPublisher``, BLOCK) puts N doubles on one variable, as fast as it can (``--rate 0``)
  or at ``--rate`` messages/s; the figure is the recorder process's CPU (every thread:
  Zenoh's receive threads included, idle cost included) from the first put until the last
  line is in its alog;
* where ``MOOS_BIN`` names a folder holding ``MOOSDB`` and ``pLogger`` (core-moos, built by
  hand): the same N doubles posted into a MOOSDB by fleetlog's asyncio MOOS client (as fast
  as it can, or at ``--rate``) and logged by a real pLogger (AppTick ``--plogger-tick``, 50
  by default: its loss-free best); the figures are pLogger's CPU and the MOOSDB's, which does
  the routing that Zenoh does inside fleetlog's process, until pLogger's alog holds every
  line or no more come for 5 s (how many it logged is printed: pLogger drops what its
  queues cannot hold, and what it drops costs it nothing).

CPU is read from ``/proc/PID/task/*/schedstat``; the recorder's Zenoh runtime threads (by
name: ``rx-N``, ``tx-N``, ``net-N``, ``app-N``, ``tokio-*``) are also summed apart, the part of
its cost that is Zenoh's Rust code receiving the samples, before any of fleetlog's. Each
figure is CPU-seconds per 100,000 messages: median [min–max] over the rounds, with the load
average beside it::

    MOOS_BIN=/path/to/core-moos/build/bin python bench/recorder_cpu.py -n 100000 --rounds 3

``--also TREE`` adds, in each round, the same fleetlog round run from another source tree
(``PYTHONPATH=TREE``), for a before/after pair in one run. ``--knob KEY=VALUE`` (repeatable)
adds the same fleetlog round of this tree with those environment variables for the recorder
alone (a Zenoh setting, e.g. ``--knob 'ZENOH_RUNTIME=(rx: (worker_threads: 1))'``).
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

from benchlib import (
    END,
    Helper,
    PLogger,
    RecorderProcess,
    Tail,
    cpu_ns,
    free_port,
    loadavg,
    parse_env,
    spread,
    zenoh_cpu_ns,
)

BRIDGE = Path(__file__).resolve().with_name("bridge.py")


def wait_lines(
    alog: Path, name: bytes, n: int, progress: bytes | None = None, timeout: float = 300.0
) -> int:
    """Wait until ``alog`` holds ``n`` lines of ``name`` (or no line of ``progress`` comes for 5 s).

    ``progress`` is ``name`` by default.
    """
    progress = name if progress is None else progress
    deadline = time.monotonic() + timeout
    while not alog.exists() and time.monotonic() < deadline:
        time.sleep(0.05)
    tail = Tail(alog)
    count = 0
    quiet_since = time.monotonic()
    try:
        while count < n and time.monotonic() < deadline:
            lines = tail.read_lines()
            names = [line.split(None, 2)[1:2] for line in lines]
            count += names.count([name])
            if [progress] in names:
                quiet_since = time.monotonic()
            elif time.monotonic() - quiet_since > 5.0:
                break
            else:
                time.sleep(0.01)
    finally:
        tail.close()
    return count


def fleetlog_round(
    n: int, rate: float, work: Path, tree: Path | None = None, env: dict[str, str] | None = None
) -> dict[str, float]:
    port = free_port()
    rec = RecorderProcess(work, port, tree=tree, env=env)
    pub = Helper(
        "publisher",
        ["--connect", f"tcp/127.0.0.1:{port}", "-n", str(n), "--keys", "1", "--rate", str(rate)],
    )
    try:
        pub.read()  # ready: its publishers match the recorder's subscription
        time.sleep(0.5)
        before, zenoh_before = cpu_ns(rec.proc.pid), zenoh_cpu_ns(rec.proc.pid)
        began = time.monotonic()
        pub.send("go")
        got = wait_lines(rec.alog, END.encode(), 1, progress=b"BENCH_X0")
        used = cpu_ns(rec.proc.pid) - before
        zenoh = zenoh_cpu_ns(rec.proc.pid) - zenoh_before
        wall = time.monotonic() - began
        pub.read()
    finally:
        pub.finish()
        summary = rec.stop()
    if not got:
        raise RuntimeError(f"the recorder did not log {END}: {summary}")
    per = 1e5 / n / 1e9
    return {"fleetlog": used * per, "zenoh": zenoh * per, "fleetlog_wall": wall}


def bare_round(n: int, rate: float) -> dict[str, float]:
    """The same traffic into a bare zenoh-python subscriber that only counts (Zenoh's own cost)."""
    port = free_port()
    counter = Helper("counter", ["--listen", f"tcp/127.0.0.1:{port}", "-n", str(n + 1)])
    counter.read()
    pub = Helper(
        "publisher",
        ["--connect", f"tcp/127.0.0.1:{port}", "-n", str(n), "--keys", "1", "--rate", str(rate)],
    )
    try:
        pub.read()
        time.sleep(0.5)
        before = cpu_ns(counter.proc.pid)
        pub.send("go")
        counter.read()  # every sample and the end marker counted
        used = cpu_ns(counter.proc.pid) - before
        pub.read()
    finally:
        pub.finish()
        counter.finish()
    return {"bare": used / 1e9 * 1e5 / n}


def plogger_round(n: int, rate: float, moos_bin: Path, tick: int, work: Path) -> dict[str, float]:
    moos = PLogger(moos_bin, work, app_tick=tick)
    try:
        alog = moos.alog()
        time.sleep(0.5)
        pub = Helper(
            "moospub",
            ["--port", str(moos.port), "-n", str(n), "--var", "BENCH_X", "--rate", str(rate)],
            BRIDGE,
        )
        pub.read()
        time.sleep(0.5)
        before = (cpu_ns(moos.logger.pid), cpu_ns(moos.db.pid))
        pub.send("go")
        got = wait_lines(alog, b"BENCH_X", n)
        used = (cpu_ns(moos.logger.pid) - before[0], cpu_ns(moos.db.pid) - before[1])
        pub.read()
        pub.finish()
    finally:
        moos.close()
    per = 1e5 / n / 1e9
    return {"pLogger": used[0] * per, "MOOSDB": used[1] * per, "pLogger_logged": float(got)}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("-n", type=int, default=100_000, help="messages per round")
    parser.add_argument("--rate", type=float, default=0.0, help="msg/s; 0: a burst")
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--plogger-tick", type=int, default=50, help="pLogger's AppTick")
    parser.add_argument(
        "--also", type=Path, help="a second fleetlog source tree, run in each round (before/after)"
    )
    parser.add_argument(
        "--knob",
        action="append",
        metavar="KEY=VALUE",
        help="also this tree's recorder with this environment variable, in each round",
    )
    args = parser.parse_args()
    knob = parse_env(args.knob)
    folder = os.environ.get("MOOS_BIN", "")
    moos_bin = Path(folder) if folder and (Path(folder) / "pLogger").is_file() else None
    if moos_bin is None:
        print("MOOS_BIN unset (or no pLogger in it): no pLogger baseline", file=sys.stderr)
    rounds: list[dict[str, float]] = []
    loads: list[float] = []
    for i in range(args.rounds):
        loads.append(os.getloadavg()[0])
        row = bare_round(args.n, args.rate)
        # With --also, the two trees take turns at going first: the first of a pair can fare
        # differently on a shared machine (recorder_idle.py's A/A pair did, by ~10 %).
        also_first = args.also is not None and i % 2 == 1
        if also_first:
            with tempfile.TemporaryDirectory(prefix="fleetlog-cpu-also-") as tmp:
                row["also"] = fleetlog_round(args.n, args.rate, Path(tmp), args.also)["fleetlog"]
        with tempfile.TemporaryDirectory(prefix="fleetlog-cpu-") as tmp:
            row.update(fleetlog_round(args.n, args.rate, Path(tmp)))
        if args.also is not None and not also_first:
            with tempfile.TemporaryDirectory(prefix="fleetlog-cpu-also-") as tmp:
                row["also"] = fleetlog_round(args.n, args.rate, Path(tmp), args.also)["fleetlog"]
        if knob:
            with tempfile.TemporaryDirectory(prefix="fleetlog-cpu-knob-") as tmp:
                row["knob"] = fleetlog_round(args.n, args.rate, Path(tmp), env=knob)["fleetlog"]
        if moos_bin is not None:
            with tempfile.TemporaryDirectory(prefix="fleetlog-cpu-moos-") as tmp:
                row.update(plogger_round(args.n, args.rate, moos_bin, args.plogger_tick, Path(tmp)))
        rounds.append(row)
        print("round:", {k: round(v, 4) for k, v in row.items()}, file=sys.stderr, flush=True)

    def col(name: str) -> list[float]:
        return [r[name] for r in rounds]

    rate = f"{args.rate:,.0f} msg/s" if args.rate > 0 else "bursts"
    print(
        f"CPU-s per 100k doubles, {args.rounds} rounds of {args.n:,} ({rate}), "
        f"load {spread(loads, '{:.1f}')} (load at {loadavg()} now)"
    )
    print(f"  fleetlog record     {spread(col('fleetlog'), '{:.3f}')}")
    print(f"  of it Zenoh threads {spread(col('zenoh'), '{:.3f}')} (rx/tx/net/app, in Rust)")
    print(f"  bare subscriber     {spread(col('bare'), '{:.3f}')} (Zenoh's own cost)")
    added = [r["fleetlog"] - r["bare"] for r in rounds]
    print(f"  fleetlog - bare     {spread(added, '{:.3f}')} (what recording adds)")
    if args.also is not None:
        print(f"  the same, {args.also}  {spread(col('also'), '{:.3f}')}")
        ratios = [r["also"] / r["fleetlog"] for r in rounds]
        print(f"  {args.also} / this tree: {spread(ratios, '{:.2f}')}x")
    if knob:
        print(f"  the same with {' '.join(args.knob)}  {spread(col('knob'), '{:.3f}')}")
        ratios = [r["knob"] / r["fleetlog"] for r in rounds]
        print(f"  with the knob / without: {spread(ratios, '{:.2f}')}x")
    if moos_bin is not None:
        both = [r["pLogger"] + r["MOOSDB"] for r in rounds]
        print(f"  pLogger             {spread(col('pLogger'), '{:.3f}')}")
        print(f"  MOOSDB              {spread(col('MOOSDB'), '{:.3f}')}")
        print(f"  pLogger + MOOSDB    {spread(both, '{:.3f}')}")
        logged = spread(col("pLogger_logged"), "{:,.0f}")
        print(f"  (pLogger logged {logged} of {args.n:,})")
        ratio_both = [r["fleetlog"] / (r["pLogger"] + r["MOOSDB"]) for r in rounds]
        ratio_alone = [r["fleetlog"] / r["pLogger"] for r in rounds]
        print(f"fleetlog / (pLogger + MOOSDB): {spread(ratio_both, '{:.2f}')}x")
        print(f"fleetlog / pLogger alone:      {spread(ratio_alone, '{:.2f}')}x")
        ratio_zenoh = [r["zenoh"] / (r["pLogger"] + r["MOOSDB"]) for r in rounds]
        print(f"its Zenoh threads alone / (pLogger + MOOSDB): {spread(ratio_zenoh, '{:.2f}')}x")
    return 0


if __name__ == "__main__":
    sys.exit(main())
