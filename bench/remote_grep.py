"""Remote grep throughput against a file fetch of the same session, same vehicle, same run.

The 1M-line alog of ``bench/read_path.py`` (77 MB, written if missing) is the only file of a
session served by ``fleetlog serve`` in a subprocess with polars capped at one thread, as a
recorder caps it (``POLARS_MAX_THREADS=1``; no recorder runs: "recorder idle"). Per round,
interleaved:

* **fetch**: ``fetch_session`` of the session (1 MiB ranges, 8 in flight, sha256, fsync);
* **grep NAV_X, first**: ``FleetClient.grep`` of one variable (~9 % of the lines), every
  record read, in a copy of the session made for this grep alone (a log the server has not
  read since it started: nothing learnt of it, fleetlog.storage.purity);
* **grep NAV_X, again**: the same grep in the session itself, which the server has grepped
  before (its warm-up grep and the rounds before);
* **grep all**: every entry (``limit`` at its maximum), every record read.

Throughput is the alog's bytes over the wall time; ratios per round against the fetch.
``vehicle CPU`` is the serving process's CPU seconds (all threads) during the grep.

``--also TREE`` serves the same session from a second source tree too (``PYTHONPATH=TREE``,
its own ``fleetlog serve``), and each grep runs in a child process of the tree that serves
it (the shore side is part of the figure), the two trees alternated within each round: a
before/after pair in one run. Without it the greps run in this process, as before.

    python bench/remote_grep.py                              # 3 rounds
    python bench/remote_grep.py --rounds 3 --also ../base    # this tree against ../base
"""

from __future__ import annotations

import argparse
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from fetch_throughput import SESSION, VEHICLE, Served, fetch_round, loadavg, spread
from read_path import write_alog

from fleetlog.shore.client import FleetClient
from fleetlog.transport.session import SessionOptions
from fleetlog.wire.query import MAX_GREP_LIMIT, GrepRequest

NAV_X = GrepRequest(variables=("NAV_X",))
REQUESTS = {
    "grep NAV_X, first": NAV_X,
    "grep NAV_X, again": NAV_X,
    "grep all": GrepRequest(limit=MAX_GREP_LIMIT),
}
FIRST = "grep NAV_X, first"
#: The session a first grep reads (a fresh copy of SESSION each round).
COPY = "BENCH_1_1_2025_____00_01_00"

# One grep from a child process (the tree on its PYTHONPATH): prints seconds and records.
_CLIENT = """
import sys, time
from fleetlog.shore.client import FleetClient
from fleetlog.transport.session import SessionOptions
from fleetlog.wire.query import MAX_GREP_LIMIT, GrepRequest
endpoint, vehicle, session, which = sys.argv[1:5]
if which == "NAV_X":
    request = GrepRequest(variables=("NAV_X",))
else:
    request = GrepRequest(limit=MAX_GREP_LIMIT)
options = SessionOptions(connect=(endpoint,), multicast_scouting=False)
with FleetClient.open(options) as client:
    client.require(vehicle)
    client.grep_timeout = 600.0
    sys.stdout.write("ready\\n")
    sys.stdout.flush()
    sys.stdin.readline()
    started = time.perf_counter()
    count = sum(1 for _ in client.grep(vehicle, session, request))
    print(time.perf_counter() - started, count, flush=True)
"""


def ratio_spread(values: list[float]) -> str:
    return f"{statistics.median(values):.2f} [{min(values):.2f}-{max(values):.2f}]"


def process_cpu(pid: int) -> float:
    """Return a process's CPU seconds so far (user and system, all threads)."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def grep_round(endpoint: str, request: GrepRequest, session: str = SESSION) -> tuple[float, int]:
    options = SessionOptions(connect=(endpoint,), multicast_scouting=False)
    with FleetClient.open(options) as client:
        client.require(VEHICLE)
        client.grep_timeout = 600.0
        started = time.perf_counter()
        stream = client.grep(VEHICLE, session, request)
        count = sum(1 for _ in stream)
        seconds = time.perf_counter() - started
    return seconds, count


HERE = Path(__file__).resolve().parent.parent


def tree_env(tree: Path | None) -> tuple[dict[str, str], Path]:
    """The environment and working directory of a child process of ``tree`` (None: this).

    ``python -m``/``-c`` put the working directory first on sys.path, before PYTHONPATH:
    a child started from another tree's directory would import that tree's fleetlog.
    """
    root = HERE if tree is None else tree
    return {**os.environ, "PYTHONPATH": str(root)}, root


def child_grep_round(
    endpoint: str, name: str, tree: Path | None, session: str = SESSION
) -> tuple[float, int]:
    """The grep from a child process of ``tree`` (this tree when None); the clock is its."""
    env, cwd = tree_env(tree)
    which = "NAV_X" if name.startswith("grep NAV_X") else "all"
    child = subprocess.Popen(
        [sys.executable, "-c", _CLIENT, endpoint, VEHICLE, session, which],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
        env=env,
        cwd=cwd,
    )
    assert child.stdin is not None
    assert child.stdout is not None
    if child.stdout.readline().strip() != "ready":
        child.kill()
        raise RuntimeError("the grep client did not start")
    child.stdin.write("go\n")
    child.stdin.flush()
    seconds, count = child.stdout.readline().split()
    child.wait(60)
    return float(seconds), int(count)


class TreeServed(Served):
    """``fleetlog serve`` from a given source tree (``PYTHONPATH`` and working directory)."""

    def __init__(self, log_root: Path, tree: Path | None) -> None:
        super().__init__(log_root)
        self.tree = tree

    def __enter__(self) -> str:
        env, cwd = tree_env(self.tree)
        old_env, old_cwd = dict(os.environ), Path.cwd()
        os.environ.update(env)
        os.chdir(cwd)  # Served starts ``python -m fleetlog`` here
        try:
            return super().__enter__()
        finally:
            os.chdir(old_cwd)
            os.environ.clear()
            os.environ.update(old_env)


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--file", type=Path, default=Path("/tmp/fleetlog-bench-read.alog"))
    parser.add_argument(
        "--also", type=Path, help="a second fleetlog source tree, served in each round"
    )
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
        trees: list[Path | None] = [None] if args.also is None else [None, args.also.resolve()]
        label = {None: "this tree", **({} if args.also is None else {trees[1]: str(args.also)})}
        rates = {t: {"fetch": [], **{n: [] for n in REQUESTS}} for t in trees}
        ratios = {t: {n: [] for n in REQUESTS} for t in trees}
        cpus = {t: {n: [] for n in REQUESTS} for t in trees}
        servers = [TreeServed(work / "root", t) for t in trees]
        endpoints = [s.__enter__() for s in servers]
        try:
            for endpoint in endpoints:  # warm: polars imported
                grep_round(endpoint, NAV_X)
            for round_ in range(args.rounds):
                order = list(zip(trees, servers, endpoints, strict=True))
                if round_ % 2:
                    order.reverse()
                for tree, server, endpoint in order:
                    out = work / f"out{round_}"
                    seconds, _ = fetch_round(endpoint, out)
                    shutil.rmtree(out, ignore_errors=True)
                    fetch = size / seconds / 1e6
                    rates[tree]["fetch"].append(fetch)
                    assert server.proc is not None
                    copy = work / "root" / COPY
                    copy.mkdir()
                    shutil.copyfile(alog, copy / f"{COPY}.alog")  # a new file: nothing learnt
                    os.utime(copy / f"{COPY}.alog", (old, old))
                    for name, request in REQUESTS.items():
                        session_name = COPY if name == FIRST else SESSION
                        before = process_cpu(server.proc.pid)
                        if args.also is None:
                            seconds, _count = grep_round(endpoint, request, session_name)
                        else:
                            seconds, _count = child_grep_round(endpoint, name, tree, session_name)
                        cpus[tree][name].append(process_cpu(server.proc.pid) - before)
                        rates[tree][name].append(size / seconds / 1e6)
                        ratios[tree][name].append(rates[tree][name][-1] / fetch)
                    shutil.rmtree(copy)
                print(f"  round {round_ + 1} done, load {loadavg()}", flush=True)
        finally:
            for server in servers:
                server.__exit__()
        for tree in trees:
            print(label[tree])
            for name, values in rates[tree].items():
                line = f"  {name:18s} {spread(values)} MB/s"
                if name in ratios[tree]:
                    line += f"   x fetch {ratio_spread(ratios[tree][name])}"
                    line += f"   vehicle CPU {ratio_spread(cpus[tree][name])} s"
                print(line)
        if args.also is not None:
            this, other = trees
            for name in REQUESTS:
                pairs = zip(ratios[this][name], ratios[other][name], strict=True)
                gain = [a / b for a, b in pairs]
                print(f"{name}: this tree's x fetch / {args.also}'s: {ratio_spread(gain)}")
        print(f"load after {loadavg()}")
    finally:
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
