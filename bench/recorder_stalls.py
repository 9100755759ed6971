"""Where a late line's time went: ``fleetlog record`` instrumented, fed at a steady rate.

The recorder runs as a subprocess of this file (role ``record``): ``fleetlog record`` with
light instrumentation patched in. It notes when the drain thread takes each sample from its
FIFO (``SampleDecoder.decode``) and the sample's publish time, when each flush returns, the
drain thread's scheduler counters at each flush (``/proc/self/task/TID/schedstat``: time
on a CPU, time runnable but waiting for one), and every pass of the cyclic GC. A publisher
process puts doubles at ``--rate`` (fleetlog's ``MoosPublisher``, BLOCK).

Each line's publish → flushed time then splits into publish → taken (transport, and the FIFO
waiting for the drain thread) and taken → flushed (the recorder holding it). The time
before each flush that released a late line (since the flush before it) splits into the
drain thread's time on a CPU, its time waiting for one, and the rest (sleeping or blocked).

    python bench/recorder_stalls.py --rate 10000 --rounds 3
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from bisect import bisect_right
from pathlib import Path
from typing import Any

from benchlib import VEHICLE, CpuMeter, Helper, RecorderProcess, free_port, loadavg, percentile

BOUND = 0.020


def role_record(out: str, argv: list[str]) -> None:
    """Run ``fleetlog record`` with the instrumentation; write what it saw to ``out``."""
    import atexit
    import gc
    import threading
    from array import array

    from fleetlog.cli import main as cli_main
    from fleetlog.recorder import engine, service
    from fleetlog.transport import bus

    clock = time.time
    taken, stamps = array("d"), array("d")
    flushed, counts, waits, runs = array("d"), array("q"), array("q"), array("q")
    gcs: list[tuple[int, float, float]] = []
    tid: list[int] = []

    decode = bus.SampleDecoder.decode

    def decode_noted(self: Any, sample: Any) -> Any:
        incoming = decode(self, sample)
        if incoming is not None:
            taken.append(clock())
            stamps.append(incoming.message.time)
        return incoming

    flush = engine.Recorder.flush

    def flush_noted(self: Any) -> None:
        flush(self)
        run = wait = 0
        if tid:
            with open(f"/proc/self/task/{tid[0]}/schedstat") as f:
                run, wait = (int(x) for x in f.read().split()[:2])
        flushed.append(clock())
        counts.append(len(taken))
        waits.append(wait)
        runs.append(run)

    loop = service.RecorderService._loop

    def loop_noted(self: Any, recorder: Any) -> None:
        tid.append(threading.get_native_id())
        loop(self, recorder)

    started = [0.0]

    def on_gc(phase: str, info: dict[str, int]) -> None:
        if phase == "start":
            started[0] = time.perf_counter()
        else:
            gcs.append((info["generation"], clock(), time.perf_counter() - started[0]))

    def dump() -> None:
        body = {
            "taken": list(taken),
            "stamps": list(stamps),
            "flushed": list(flushed),
            "counts": list(counts),
            "waits": list(waits),
            "runs": list(runs),
            "gcs": gcs,
        }
        with open(out, "w") as f:
            json.dump(body, f)

    bus.SampleDecoder.decode = decode_noted  # type: ignore[method-assign]
    engine.Recorder.flush = flush_noted  # type: ignore[method-assign]
    service.RecorderService._loop = loop_noted  # type: ignore[method-assign]
    gc.callbacks.append(on_gc)
    atexit.register(dump)
    sys.argv = ["fleetlog", *argv]
    cli_main()


class InstrumentedRecorder(RecorderProcess):
    """``fleetlog record`` run through :func:`role_record`."""

    def __init__(self, workdir: Path, port: int, out: Path) -> None:
        self.workdir = workdir
        self.proc = subprocess.Popen(
            [
                sys.executable,
                __file__,
                "record",
                str(out),
                "record",
                "--vehicle",
                VEHICLE,
                "-l",
                f"tcp/127.0.0.1:{port}",
                "--no-multicast-scouting",
            ],
            cwd=workdir,
            stderr=subprocess.PIPE,
            stdout=subprocess.DEVNULL,
            text=True,
        )
        self.stderr: list[str] = []
        self.alog = self._wait_ready()


def run(rate: float, n: int, keys: int, workdir: Path) -> dict[str, Any]:
    """One instrumented run; return the recorder's notes and when publishing started."""
    port = free_port()
    out = workdir / "stalls.json"
    rec = InstrumentedRecorder(workdir, port, out)
    args = ["--connect", f"tcp/127.0.0.1:{port}", "-n", str(n), "--keys", str(keys)]
    pub = Helper("publisher", [*args, "--rate", str(rate)])
    meter = CpuMeter()
    try:
        pub.read()
        pub.send("go")
        start = time.time()
        pub.read(timeout=n / rate + 60)
        time.sleep(0.2)
    finally:
        pub.finish()
        rec.stop()
    busy, steal = meter.shares()
    notes: dict[str, Any] = json.loads(out.read_text())
    notes.update(start=start, busy=busy, steal=steal)
    return notes


def analyse(notes: dict[str, Any], n: int) -> dict[str, float]:
    """Split late lines and long flush gaps (see the module's docstring)."""
    taken, stamps = notes["taken"], notes["stamps"]
    flushed, counts = notes["flushed"], notes["counts"]
    start = notes["start"]
    e2e: list[float] = []
    before: list[float] = []
    held: list[float] = []
    late_before = late_held = 0
    late_flushes: set[int] = set()
    for i, (t, stamp) in enumerate(zip(taken, stamps, strict=True)):
        if stamp < start:
            continue  # the recorder's own posts at start-up
        j = bisect_right(counts, i)
        if j >= len(flushed):
            continue
        total = flushed[j] - stamp
        e2e.append(total)
        before.append(t - stamp)
        held.append(flushed[j] - t)
        if total > BOUND:
            late_flushes.add(j)
            if t - stamp >= flushed[j] - t:
                late_before += 1
            else:
                late_held += 1
    gap = wait = run = 0.0
    for k in sorted(late_flushes):
        if k > 0:
            gap += flushed[k] - flushed[k - 1]
            wait += (notes["waits"][k] - notes["waits"][k - 1]) / 1e9
            run += (notes["runs"][k] - notes["runs"][k - 1]) / 1e9
    during = [g for g in notes["gcs"] if start <= g[1] <= start + 60]
    e2e.sort()
    before.sort()
    held.sort()
    late = late_before + late_held
    return {
        "lines": len(e2e),
        "p50": percentile(e2e, 0.5) * 1e3,
        "p99": percentile(e2e, 0.99) * 1e3,
        "max": e2e[-1] * 1e3 if e2e else float("nan"),
        "over": late / len(e2e) if e2e else float("nan"),
        "before_p99": percentile(before, 0.99) * 1e3,
        "held_p99": percentile(held, 0.99) * 1e3,
        "held_max": held[-1] * 1e3 if held else float("nan"),
        "late_before": late_before / late if late else float("nan"),
        "gap": gap * 1e3,
        "wait": wait / gap if gap else float("nan"),
        "run": run / gap if gap else float("nan"),
        "gc_passes": len(during),
        "gc_max": max((g[2] for g in during), default=0.0) * 1e3,
        "busy": notes["busy"],
        "steal": notes["steal"],
    }


def main() -> int:
    if len(sys.argv) > 2 and sys.argv[1] == "record":
        role_record(sys.argv[2], sys.argv[3:])
        return 0
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--rate", type=float, default=10_000.0)
    parser.add_argument("--seconds", type=float, default=5.0)
    parser.add_argument("--keys", type=int, default=4)
    parser.add_argument("--rounds", type=int, default=3)
    args = parser.parse_args()
    n = int(args.rate * args.seconds)
    print(f"{args.rate:,.0f}/s for {args.seconds:g} s, {args.rounds} round(s), load {loadavg()}")
    totals = {"gap": 0.0, "wait": 0.0, "run": 0.0}
    with tempfile.TemporaryDirectory(prefix="fleetlog-stalls-") as tmp:
        for r in range(args.rounds):
            workdir = Path(tmp) / f"r{r}"
            workdir.mkdir()
            a = analyse(run(args.rate, n, args.keys, workdir), n)
            for key in ("wait", "run"):
                if a["gap"]:
                    totals[key] += a[key] * a["gap"]
            totals["gap"] += a["gap"]
            late_before = "-" if a["over"] == 0 else f"{a['late_before']:.0%}"
            print(
                f"  round {r + 1}: publish → flushed p50 {a['p50']:.2f} p99 {a['p99']:.2f} "
                f"max {a['max']:.1f} ms, {a['over']:.2%} over 20 ms "
                f"({late_before} of them late mostly before being taken)\n"
                f"    publish → taken p99 {a['before_p99']:.2f} ms; taken → flushed p99 "
                f"{a['held_p99']:.2f} max {a['held_max']:.1f} ms\n"
                f"    before the flushes that released late lines: {a['gap']:.0f} ms in all, "
                f"the drain thread waiting for a CPU {a['wait']:.0%} of it, running "
                f"{a['run']:.0%}\n"
                f"    GC passes while publishing: {a['gc_passes']}, longest "
                f"{a['gc_max']:.2f} ms; CPUs {a['busy']:.0%} busy, {a['steal']:.0%} stolen "
                f"(load {loadavg()})",
                flush=True,
            )
    if totals["gap"]:
        print(
            f"all rounds: {totals['gap']:.0f} ms before flushes that released late lines, "
            f"{totals['wait'] / totals['gap']:.0%} waiting for a CPU, "
            f"{totals['run'] / totals['gap']:.0%} running, the rest sleeping or blocked"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
