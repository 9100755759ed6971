"""What bounding the recorder's queue by time costs its loss-free rate (issue 11).

The recorder's FIFOs hold what it received and has not logged; what a SIGKILL can lose is
that backlog. The old bound, 65,536 samples, was 1-1.8 s at full rate. This runs the same
full-rate publisher (fleetlog's MoosPublisher, BLOCK: a full queue holds it back) against
``fleetlog record --queue Q`` for each Q, rounds interleaved, and prints the loss-free rate
(every value checked, ``lost 0``), its ratio to the old bound's in the same round, and the
queue in seconds at the rate measured (Q / rate).

    python bench/queue_bound.py                  # Q = 65536, 8192, 2048; 200k samples, 3 rounds
    python bench/queue_bound.py --queues 65536 8192 --rounds 5
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
    spread,
    summary_counts,
)


def run(n: int, keys: int, queue: int, workdir: Path) -> dict[str, float | bool]:
    port = free_port()
    rec = RecorderProcess(workdir, port, ["--queue", str(queue), "--no-serve"])
    pub: Helper | None = None
    seen_end = None
    try:
        tail = Tail(rec.alog)
        pub = Helper(
            "publisher", ["--connect", f"tcp/127.0.0.1:{port}", "-n", str(n), "--keys", str(keys)]
        )
        pub.read()
        pub.send("go")
        sent = pub.read()
        marker = END.encode()
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
    ok = (
        sum(counts.values()) == n
        and all(exact.values())
        and summary_counts(summary).get("lost", -1) == 0
    )
    rate = n / (seen_end - sent["t0"]) if seen_end else 0.0
    return {"rate": rate, "ok": ok}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("-n", type=int, default=200_000)
    parser.add_argument("--keys", type=int, default=4)
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--queues", type=int, nargs="+", default=[65536, 8192, 2048])
    args = parser.parse_args()
    base = args.queues[0]
    rates: dict[int, list[float]] = {q: [] for q in args.queues}
    ratios: dict[int, list[float]] = {q: [] for q in args.queues}
    all_ok = True
    print(f"load before: {loadavg()}")
    with tempfile.TemporaryDirectory() as tmp:
        for r in range(args.rounds):
            got: dict[int, float] = {}
            for q in args.queues:
                workdir = Path(tmp) / f"r{r}q{q}"
                workdir.mkdir()
                result = run(args.n, args.keys, q, workdir)
                all_ok &= bool(result["ok"])
                got[q] = float(result["rate"])
                rates[q].append(got[q])
                print(
                    f"round {r + 1} queue {q:6d}: {got[q]:9,.0f}/s loss-free={result['ok']}",
                    flush=True,
                )
            for q in args.queues:
                ratios[q].append(got[q] / got[base] if got[base] else 0.0)
    print(f"load after: {loadavg()}")
    print(
        f"\n| queue (samples) | loss-free rate | / queue {base} | queue in seconds at that rate |"
    )
    print("|---|---|---|---|")
    for q in args.queues:
        med = statistics.median(rates[q])
        rate, ratio = spread(rates[q], "{:,.0f}/s"), spread(ratios[q], "{:.2f}×")
        print(f"| {q} | {rate} | {ratio} | {q / med:.3f} s |")
    print(f"\nevery run loss-free (all values, lost 0): {all_ok}")
    return 0 if all_ok else 1


if __name__ == "__main__":
    sys.exit(main())
