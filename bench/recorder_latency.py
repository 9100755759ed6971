"""Publish → flushed-line latency of ``fleetlog record``, against a bare subscriber's latency.

A publisher process (fleetlog's ``MoosPublisher``, BLOCK) puts doubles at a steady rate; each
sample's attachment carries its publish time (``MoosPublisher`` stamps ``time.time()`` just
before the put). Two consumers, in the same run:

(a) bare: a zenoh-python FIFO subscriber; latency = receive time − publish time;
(b) recorder: ``fleetlog record --vehicle bench`` (no mission) as a subprocess, while this
    process tails its alog: it polls the file every ``--poll`` seconds, reads only what the
    OS has, and notes when each complete line first appears; latency = that moment −
    (LOGSTART + the line's time column, which is the publish time to 10 µs).

So (b) is what a reader (or a ``kill -9``) sees: transport + queueing + the recorder's
work + its flush policy + the poll interval. The issue requires ≤ 20 ms for plain logs.
Percentiles are over every sample of a run; figures are the median [min–max] over rounds.

    python bench/recorder_latency.py                       # 1,000/s and 10,000/s, 5 s each
    python bench/recorder_latency.py --rates 1000,10000,40000 --seconds 3 --rounds 5

``--also TREE`` adds the recorder from another source tree in each round (before/after);
``--knob KEY=VALUE`` (repeatable) adds this tree's recorder with those environment variables
(a Zenoh setting); ``--nice N`` adds this tree's recorder at niceness N (a unit's ``Nice=``;
below 0 needs root); each round alternates which recorder runs first.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

from benchlib import (
    END,
    CpuMeter,
    Helper,
    RecorderProcess,
    Tail,
    free_port,
    key_names,
    loadavg,
    parse_env,
    percentile,
    spread,
    summary_counts,
)

BOUND = 0.020


def figures(latencies: list[float]) -> dict[str, float]:
    """p50/p99/max in ms, and the share above the 20 ms bound."""
    lat = sorted(latencies)
    over = sum(1 for x in lat if x > BOUND)
    return {
        "n": len(lat),
        "p50": percentile(lat, 0.50) * 1e3,
        "p99": percentile(lat, 0.99) * 1e3,
        "max": lat[-1] * 1e3 if lat else float("nan"),
        "over": over / len(lat) if lat else float("nan"),
    }


def publisher(port: int, n: int, keys: int, rate: float) -> Helper:
    args = ["--connect", f"tcp/127.0.0.1:{port}", "-n", str(n), "--keys", str(keys)]
    return Helper("publisher", [*args, "--rate", str(rate)])


def run_bare(rate: float, n: int, keys: int) -> dict[str, float]:
    port = free_port()
    stamps = Helper("stamps", ["--listen", f"tcp/127.0.0.1:{port}", "-n", str(n + 1)])
    stamps.read()
    pub = publisher(port, n, keys, rate)
    try:
        pub.read()
        pub.send("go")
        pub.read()
        got = stamps.read(timeout=n / rate + 60)
    finally:
        pub.finish()
        stamps.finish()
    return figures(got["latencies"])


def run_recorder(
    rate: float,
    n: int,
    keys: int,
    workdir: Path,
    poll: float,
    tree: Path | None = None,
    env: dict[str, str] | None = None,
    nice: int | None = None,
) -> dict[str, float]:
    port = free_port()
    rec = RecorderProcess(workdir, port, tree=tree, env=env, nice=nice)
    names = {name.encode() for name in key_names(keys)}
    marker = END.encode()
    latencies: list[float] = []
    logstart = None
    pub: Helper | None = None
    try:
        tail = Tail(rec.alog)
        pub = publisher(port, n, keys, rate)
        pub.read()
        pub.send("go")
        clock = time.time
        deadline = time.monotonic() + n / rate + 60
        done = False
        while not done and time.monotonic() < deadline:
            lines = tail.read_lines()
            seen = clock()
            for line in lines:
                if line.startswith(b"%% LOGSTART"):
                    logstart = float(line.split()[2])
                    continue
                fields = line.split(None, 2)
                if len(fields) < 2:
                    continue
                if fields[1] in names and logstart is not None:
                    latencies.append(seen - (logstart + float(fields[0])))
                elif fields[1] == marker:
                    done = True
            time.sleep(poll)
        tail.close()
        pub.read()
    finally:
        if pub is not None:
            pub.finish()
        summary = rec.stop()
    result = figures(latencies)
    stats = summary_counts(summary)
    result["lost"] = float(stats.get("lost", -1))
    result["skewed"] = float(stats.get("skewed", -1))
    result["missing"] = float(n - len(latencies))
    return result


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--rates", default="1000,10000", help="samples/s, comma separated")
    parser.add_argument("--seconds", type=float, default=5.0, help="publishing time per run")
    parser.add_argument("--keys", type=int, default=4)
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--poll", type=float, default=0.0005, help="alog poll interval (s)")
    parser.add_argument(
        "--also", type=Path, help="the recorder also from this source tree (before/after)"
    )
    parser.add_argument(
        "--knob",
        action="append",
        metavar="KEY=VALUE",
        help="also this tree's recorder with this environment variable, in each round",
    )
    parser.add_argument(
        "--nice", type=int, help="also this tree's recorder at this niceness, in each round"
    )
    args = parser.parse_args()
    knob = parse_env(args.knob)
    rates = [float(r) for r in args.rates.split(",")]
    print(
        f"rates {', '.join(f'{r:,.0f}/s' for r in rates)}, {args.seconds:g} s each, "
        f"{args.rounds} round(s), alog polled every {args.poll * 1e3:g} ms, load {loadavg()}"
    )
    results: dict[tuple[float, str], list[dict[str, float]]] = {}
    ok = True
    Recorder = tuple[str, Path | None, dict[str, str] | None, int | None]
    recorders: list[Recorder] = [("rec", None, None, None)]
    if args.also is not None:
        recorders.append(("also", args.also, None, None))
    if knob:
        recorders.append(("knob", None, knob, None))
    if args.nice is not None:
        recorders.append(("nice", None, None, args.nice))
    with tempfile.TemporaryDirectory(prefix="fleetlog-lat-") as tmp:
        for r in range(args.rounds):
            for rate in rates:
                n = int(rate * args.seconds)
                bare = run_bare(rate, n, args.keys)
                results.setdefault((rate, "bare"), []).append(bare)
                # The order of the recorders alternates: the first of a round often fares
                # differently on a shared machine.
                for who, tree, env, nice in recorders if r % 2 == 0 else recorders[::-1]:
                    rundir = Path(tmp) / f"r{r}-{int(rate)}-{who}"
                    rundir.mkdir()
                    meter = CpuMeter()
                    rec = run_recorder(rate, n, args.keys, rundir, args.poll, tree, env, nice)
                    rec["busy"], rec["steal"] = meter.shares()
                    results.setdefault((rate, who), []).append(rec)
                    if who == "rec" and (rec["missing"] or rec["lost"] or rec["max"] > BOUND * 1e3):
                        ok = False
                    label = "recorder" if who == "rec" else f"--{who}"
                    head = (
                        f"bare p50 {bare['p50']:.3f} p99 {bare['p99']:.3f} | "
                        if who == "rec"
                        else ""
                    )
                    print(
                        f"  round {r + 1} {rate:>8,.0f}/s: {head}{label} p50 {rec['p50']:.3f} "
                        f"p99 {rec['p99']:.3f} max {rec['max']:.2f} ms, "
                        f"{rec['over']:.2%} > 20 ms, missing {rec['missing']:.0f}, "
                        f"lost {rec['lost']:.0f} (load {loadavg()}, CPUs {rec['busy']:.0%} busy, "
                        f"{rec['steal']:.0%} stolen)",
                        flush=True,
                    )
    print()
    print("latency in ms, median [min–max] over rounds:")
    print(f"  {'rate':>8}  {'':9} {'p50':<22} {'p99':<22} {'max':<22}")
    for rate in rates:
        for who, label in (
            ("bare", "bare sub"),
            ("rec", "recorder"),
            ("also", "--also"),
            ("knob", "--knob"),
            ("nice", "--nice"),
        ):
            if (rate, who) not in results:
                continue
            rows = results[(rate, who)]
            cells = [spread([x[q] for x in rows], "{:.2f}") for q in ("p50", "p99", "max")]
            print(f"  {rate:>8,.0f}  {label:9} {cells[0]:<22} {cells[1]:<22} {cells[2]:<22}")
        bare_rows, rec_rows = results[(rate, "bare")], results[(rate, "rec")]
        for q in ("p50", "p99"):
            ratios = [b[q] / a[q] for a, b in zip(bare_rows, rec_rows, strict=True)]
            print(f"  {'':8}  recorder/bare {q}: {spread(ratios, '{:.1f}')}×")
        over = spread([x["over"] * 100 for x in rec_rows], "{:.2f}")
        print(f"  {'':8}  recorder lines over 20 ms: {over} %")
        for who in ("also", "knob", "nice"):
            if (rate, who) in results:
                others = results[(rate, who)]
                ratios = [b["p99"] / a["p99"] for a, b in zip(rec_rows, others, strict=True)]
                print(f"  {'':8}  --{who} / recorder p99: {spread(ratios, '{:.2f}')}×")
    worst = max(x["max"] for (_, who), rows in results.items() if who == "rec" for x in rows)
    if args.also is not None:
        print(f"  --also: {args.also}")
    if knob:
        print(f"  --knob: {' '.join(args.knob)}")
    if args.nice is not None:
        print(f"  --nice: {args.nice}")
    print(f"every line flushed within 20 ms of publishing: {'yes' if ok else 'NO'}", end="")
    print(f" (worst {worst:.2f} ms)")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
