"""Loss-free recording rate of ``fleetlog record`` against a bare Zenoh subscriber, same run.

Three consumers, each fed by the same publisher process (fleetlog's ``MoosPublisher``: BLOCK
congestion control, reliable, fleetlog's encoding and attachment) putting N small doubles on
a few keys as fast as it can, then an end marker on the same subscription:

(a) bare: a zenoh-python process with one FIFO subscriber (``try_recv() or recv()``) that only
    counts; rate = N / (last sample received − first put);
(b) format: this process formatting and writing the same N alog lines with LineFormatter and
    a buffered file (no Zenoh, flushed every 10 ms); rate = N / loop time;
(c) recorder: ``fleetlog record --vehicle bench`` (no mission: wildcard logging) as a
    subprocess; rate = N / (end marker's line seen in the alog − first put). Afterwards the
    alog is counted per key and every value checked (zero loss, no duplicates), and the
    recorder's summary line must say ``lost 0``.

The rounds interleave a, b, c so that load from other users of the machine hits all three;
figures are the median [min–max] over rounds, ratios are taken within each round.

    python bench/recorder_rate.py                 # 200k samples, 4 keys, 3 rounds
    python bench/recorder_rate.py -n 100000 --rounds 5
    python bench/recorder_rate.py --only bare --only recorder --also /path/to/old/tree
    python bench/recorder_rate.py --only bare --only recorder --knob 'ZENOH_RUNTIME=(...)'

``--knob KEY=VALUE`` (repeatable) adds, in each round, (c) with those environment variables
for the recorder alone (a Zenoh setting), against (c) without them.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

from benchlib import (
    END,
    Helper,
    RecorderProcess,
    Tail,
    count_alog,
    free_port,
    key_names,
    loadavg,
    parse_env,
    spread,
    summary_counts,
)

from fleetlog.moos.alog import LineFormatter


def publisher(port: int, n: int, keys: int, raw: bool) -> Helper:
    args = ["--connect", f"tcp/127.0.0.1:{port}", "-n", str(n), "--keys", str(keys)]
    return Helper("publisher", [*args, "--raw"] if raw else args)


def run_bare(n: int, keys: int, raw: bool) -> dict[str, float]:
    """(a) the bare counting subscriber."""
    port = free_port()
    counter = Helper("counter", ["--listen", f"tcp/127.0.0.1:{port}", "-n", str(n + 1)])
    counter.read()
    pub = publisher(port, n, keys, raw)
    try:
        pub.read()
        pub.send("go")
        sent = pub.read()
        got = counter.read()
    finally:
        pub.finish()
        counter.finish()
    return {
        "rate": n / (got["last"] - sent["t0"]),
        "rate_rx": n / (got["last"] - got["first"]),
        "pub_rate": n / (sent["t1"] - sent["t0"]),
    }


def run_format(n: int, keys: int, workdir: Path) -> dict[str, float]:
    """(b) format and write alog lines in one thread, no Zenoh."""
    names = key_names(keys)
    fmt = LineFormatter()
    double = fmt.double
    clock = time.time
    perf = time.perf_counter
    logstart = clock()
    path = workdir / "format.alog"
    with open(path, "wb", buffering=1 << 16) as f:
        write = f.write
        start = perf()
        last_flush = start
        for i in range(n):
            line = double(clock() - logstart, names[i % keys], "bench", float(i // keys))
            write(line.encode("utf-8", "surrogateescape"))
            if not i & 127:
                now = perf()
                if now - last_flush >= 0.01:
                    f.flush()
                    last_flush = now
        f.flush()
        elapsed = perf() - start
    path.unlink()
    return {"rate": n / elapsed}


def run_recorder(
    n: int,
    keys: int,
    workdir: Path,
    raw: bool,
    tree: Path | None = None,
    env: dict[str, str] | None = None,
) -> dict[str, object]:
    """(c) ``fleetlog record`` as a subprocess, tailing its alog for the end marker."""
    port = free_port()
    rec = RecorderProcess(workdir, port, tree=tree, env=env)
    pub: Helper | None = None
    try:
        tail = Tail(rec.alog)
        pub = publisher(port, n, keys, raw)
        pub.read()
        pub.send("go")
        sent = pub.read()
        marker = END.encode()
        seen_end = None
        deadline = time.monotonic() + max(60.0, n / 5000)
        while seen_end is None and time.monotonic() < deadline:
            for line in tail.read_lines():
                if marker in line:
                    seen_end = time.time()
            if seen_end is None:
                time.sleep(0.005)
        tail.close()
    finally:
        if pub is not None:
            pub.finish()
        summary = rec.stop()
    counts, exact = count_alog(rec.alog, key_names(keys))
    logged = sum(counts.values())
    stats = summary_counts(summary)
    loss_free = logged == n and all(exact.values()) and stats.get("lost", -1) == 0
    return {
        "rate": n / (seen_end - sent["t0"]) if seen_end else 0.0,
        "pub_rate": n / (sent["t1"] - sent["t0"]),
        "logged": logged,
        "loss_free": loss_free,
        "summary": summary,
    }


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("-n", type=int, default=200_000, help="samples per run (default 200k)")
    parser.add_argument("--keys", type=int, default=4, help="distinct keys (default 4)")
    parser.add_argument("--rounds", type=int, default=3, help="a/b/c rounds (default 3)")
    parser.add_argument(
        "--raw",
        action="store_true",
        help="feed (a) and (c) with pre-encoded zenoh puts instead of MoosPublisher, so that "
        "the publisher bounds the bare subscriber less",
    )
    parser.add_argument(
        "--only", choices=("bare", "format", "recorder"), action="append", help="run only these"
    )
    parser.add_argument(
        "--also", type=Path, help="(c) also from this source tree, in each round (before/after)"
    )
    parser.add_argument(
        "--knob",
        action="append",
        metavar="KEY=VALUE",
        help="(c) also with this environment variable for the recorder, in each round",
    )
    args = parser.parse_args()
    knob = parse_env(args.knob)
    which = args.only or ["bare", "format", "recorder"]
    if args.also is not None:
        which.append("also")
    if knob:
        which.append("knob")
    n, keys = args.n, args.keys
    feed = "pre-encoded zenoh puts" if args.raw else "MoosPublisher"
    print(
        f"{n:,} doubles on {keys} keys per run from {feed} (BLOCK), {args.rounds} round(s), "
        f"load {loadavg()}"
    )
    results: dict[str, list[dict[str, object]]] = {w: [] for w in which}
    ok = True
    with tempfile.TemporaryDirectory(prefix="fleetlog-bench-") as tmp:
        workdir = Path(tmp)
        for r in range(args.rounds):
            line = []
            # The order alternates: the first of a round can fare differently on a shared
            # machine (recorder_idle.py's A/A pair did, by ~10 %).
            for w in which if r % 2 == 0 else which[::-1]:
                if w == "bare":
                    res: dict[str, object] = dict(run_bare(n, keys, args.raw))
                elif w == "format":
                    res = dict(run_format(n, keys, workdir))
                else:
                    rundir = workdir / f"{w}{r}"
                    rundir.mkdir()
                    tree = args.also if w == "also" else None
                    env = knob if w == "knob" else None
                    res = run_recorder(n, keys, rundir, args.raw, tree, env)
                    if not res["loss_free"]:
                        ok = False
                results[w].append(res)
                extra = ""
                if w in ("recorder", "also", "knob"):
                    verdict = "loss-free" if res["loss_free"] else f"LOSS: {res['summary']}"
                    extra = f" ({verdict})"
                line.append(f"{w} {res['rate']:,.0f}/s{extra}")
            print(f"  round {r + 1}: " + ", ".join(line), f"(load {loadavg()})", flush=True)

    def rates(w: str, field: str = "rate") -> list[float]:
        return [float(x[field]) for x in results.get(w, [])]  # type: ignore[arg-type]

    print()
    print("samples/s, median [min–max]:")
    if "bare" in which:
        print(f"  (a) bare subscriber        {spread(rates('bare'))}")
        print(f"      its publisher alone    {spread(rates('bare', 'pub_rate'))} (put loop)")
    if "format" in which:
        print(f"  (b) format+write loop      {spread(rates('format'))}")
    if "recorder" in which:
        free = all(bool(x["loss_free"]) for x in results["recorder"])
        print(f"  (c) fleetlog record        {spread(rates('recorder'))}", end="")
        print("  loss-free in every run" if free else "  LOSS in some run")
    if "also" in which:
        print(f"  (c) from {args.also}  {spread(rates('also'))}")
    if "knob" in which:
        free = all(bool(x["loss_free"]) for x in results["knob"])
        print(f"  (c) with {' '.join(args.knob)}  {spread(rates('knob'))}", end="")
        print("  loss-free in every run" if free else "  LOSS in some run")
    if "bare" in which:
        pairs = [("recorder", "recorder / bare"), ("format", "format / bare")]
        pairs.append(("also", "(c) from --also / bare"))
        pairs.append(("knob", "(c) with --knob / bare"))
        for w, label in pairs:
            if w in which:
                ratios = [a / b for a, b in zip(rates(w), rates("bare"), strict=True)]
                print(f"  {label:<26} {spread(ratios, '{:.2f}')}×")
    if "recorder" in which and "knob" in which:
        ratios = [a / b for a, b in zip(rates("knob"), rates("recorder"), strict=True)]
        print(f"  {'with --knob / without':<26} {spread(ratios, '{:.2f}')}×")
    if "recorder" in which and "format" in which:
        ratios = [a / b for a, b in zip(rates("recorder"), rates("format"), strict=True)]
        print(f"  {'recorder / format':<26} {spread(ratios, '{:.2f}')}×")
    if "recorder" in which:
        target = statistics.median(rates("recorder")) >= 50_000 and ok
        print(f"target ≥ 50,000/s loss-free: {'met' if target else 'NOT met'}")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
