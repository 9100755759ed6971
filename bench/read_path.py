"""The columnar read path against its baselines, on the same file, in one run.

Writes (or reuses) a synthetic 1M-line alog shaped like a MOOS-IvP mission log (70 %
doubles from 8 variables, 30 % strings, ~77 bytes a line), then times, interleaved, per
round:

(a) split: a bare Python loop, ``for line in file: line.split(None, 3)`` (the baseline);
(b) reader: ``AlogReader.batches()`` of typed columns (every column of SCHEMA but ``raw``);
(c) info: ``fleetlog.tools.scan_log`` (what ``fleetlog info`` computes);
(d) grep: ``fleetlog.tools.grep_log`` of NAV_X to /dev/null (what ``fleetlog grep`` does);
(e) line parser: the oracle's ``AlogReader.entries()`` (tests/alog_oracle.py), the old path.

Rates are lines (entries) per second; ratios per round against (a); ``cpu`` is the process's
CPU seconds for the run (all threads), the figure that holds when the shared machine is
loaded. Run it short: the machine's two cores are shared.

    python bench/read_path.py                 # 1M lines, 3 rounds
    python bench/read_path.py -n 300000 --rounds 2 --threads 1
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
LOGSTART = 1750334690.048564


def write_alog(path: Path, n: int) -> None:
    import random

    from fleetlog.moos.alog import LineFormatter, format_banner

    rnd = random.Random(1)
    fmt = LineFormatter()
    doubles = [
        ("NAV_X", "pNav"),
        ("NAV_Y", "pNav"),
        ("NAV_HEADING", "pNav"),
        ("NAV_SPEED", "pNav"),
        ("DESIRED_RUDDER", "pMarinePIDV22"),
        ("DESIRED_THRUST", "pMarinePIDV22"),
        ("DB_TIME", "MOOSDB_alpha"),
        ("IVPHELM_ITER", "pHelmIvP"),
    ]
    strings = [
        ("NODE_REPORT_LOCAL", "pNodeReporter"),
        ("DEPLOY", "pHelmIvP:HELM_VAR_INIT"),
        ("APPCAST", "pHelmIvP"),
        ("VIEW_POINT", "pHelmIvP"),
        ("IVPHELM_SUMMARY", "pHelmIvP"),
    ]
    t = 0.0
    with path.open("w") as out:
        out.write(format_banner("./x/x.alog", LOGSTART, "Thu Jan  1 00:00:00 1970"))
        for i in range(n):
            t += rnd.random() * 0.002
            if rnd.random() < 0.7:
                key, src = rnd.choice(doubles)
                out.write(fmt.double(t, key, src, rnd.uniform(-1000, 1000)))
            else:
                key, src = rnd.choice(strings)
                if key == "NODE_REPORT_LOCAL":
                    value = (
                        f"NAME=alpha,X={rnd.uniform(-100, 100):.2f},Y={rnd.uniform(-100, 100):.2f}"
                        f",SPD=1.2,HDG=90,DEP=0,LAT=43.82,LON=-70.33,TYPE=kayak,MODE=SURVEYING,"
                        f"TIME={LOGSTART + t:.2f},LENGTH=4"
                    )
                else:
                    value = f"x={i % 100},y={i % 37},label=pt{i}"
                out.write(fmt.string(t, key, src, value))


def run_split(path: Path) -> int:
    n = 0
    with path.open(encoding="utf-8", errors="surrogateescape") as f:
        for line in f:
            line.split(None, 3)
            n += 1
    return n


def run_reader(path: Path) -> int:
    from fleetlog.storage.columnar import SCHEMA, AlogReader

    columns = [c for c in SCHEMA if c != "raw"]
    with AlogReader(path) as reader:
        return sum(b.height for b in reader.batches(columns))


def run_info(path: Path) -> int:
    from fleetlog.tools import open_log, scan_log

    return scan_log(open_log(path)).entries


def run_grep(path: Path) -> int:
    from fleetlog.storage.select import Selection
    from fleetlog.tools import grep_log, open_log

    with open(os.devnull, "wb") as out:
        return grep_log(open_log(path), out, Selection(keys=("NAV_X",))).scanned


def run_oracle(path: Path) -> int:
    sys.path.insert(0, str(HERE.parent / "tests"))
    from alog_oracle import AlogReader as Oracle

    with Oracle(path) as reader:
        return sum(1 for _ in reader.entries())


RUNS = {
    "split": run_split,
    "reader": run_reader,
    "info": run_info,
    "grep": run_grep,
    "line parser": run_oracle,
}


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("-n", type=int, default=1_000_000)
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--file", type=Path, default=Path("/tmp/fleetlog-bench-read.alog"))
    parser.add_argument("--skip", default="", help="comma-separated runs to leave out")
    args = parser.parse_args()
    os.environ["POLARS_MAX_THREADS"] = str(args.threads)
    if not args.file.exists():
        write_alog(args.file, args.n)
    import polars  # noqa: F401 - import outside the timings (about 0.3 s, once a process)

    lines = sum(1 for _ in args.file.open("rb"))
    size = args.file.stat().st_size
    print(
        f"file {args.file} {lines:,} lines {size / 1e6:.1f} MB; polars threads {args.threads};"
        f" load {os.getloadavg()[0]:.2f}"
    )
    rates: dict[str, list[float]] = {name: [] for name in RUNS}
    ratios: dict[str, list[float]] = {name: [] for name in RUNS}
    cpus: dict[str, list[float]] = {name: [] for name in RUNS}
    skip = set(filter(None, args.skip.split(",")))
    for _ in range(args.rounds):
        base = 0.0
        for name, run in RUNS.items():
            if name in skip:
                continue
            start, cpu = time.perf_counter(), time.process_time()
            run(args.file)
            rate = lines / (time.perf_counter() - start)
            rates[name].append(rate)
            cpus[name].append(time.process_time() - cpu)
            if name == "split":
                base = rate
            ratios[name].append(rate / base)
    for name in RUNS:
        if not rates[name]:
            continue
        r = sorted(rates[name])
        q = sorted(ratios[name])
        c = sorted(cpus[name])
        print(
            f"{name:12s} {r[len(r) // 2] / 1e6:5.2f}M lines/s [{r[0] / 1e6:.2f}-{r[-1] / 1e6:.2f}]"
            f"  x split {q[len(q) // 2]:.2f} [{q[0]:.2f}-{q[-1]:.2f}]"
            f"  cpu {c[len(c) // 2]:.2f} s [{c[0]:.2f}-{c[-1]:.2f}]"
        )
    print(f"load after {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
