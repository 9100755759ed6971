"""Replay throughput (as fast as possible) and 1x timing error, against baselines, same run.

Throughput: a synthetic alog of N entries (4 variables, doubles and strings, as pLogger
writes them) is

(a) parse: read with AlogReader.entries() and nothing else;
(b) schedule: read through the replay schedule (parse + re-sort window + duplicate check);
(c) bare put: N pre-parsed values published with MoosPublisher (BLOCK) to a bare FIFO counter
    process, no file at all; rate = N / (last sample received - first put);
(d) replay: the Player, as fast as possible, publishing through ReplayLink to the same kind
    of counter; rate = N / (last sample received - start).

Rounds interleave (a)-(d); figures are median [min-max], ratios per round; the CPU ratio is
the publishing thread's CPU seconds in (c) over those in (d), which holds under load.

Timing at 1x: a 3 s log of entries 0.2-5 ms apart (bursts and gaps) is played at rate 1 to a
counter; the player's own histogram gives how late each entry was published after its due
time (p50/p99/max), for three clocks: sleep only (no spin; the baseline), sleep + 1 ms spin
(what fleetlog uses), and the same with the rich progress line redrawing 4 times a second.

    python bench/replay_rate.py                      # 200k entries, 3 rounds
    python bench/replay_rate.py -n 100000 --rounds 2 --timing-seconds 2
"""

from __future__ import annotations

import argparse
import io
import random
import tempfile
import time
from pathlib import Path

from benchlib import VEHICLE, Helper, free_port, loadavg, spread
from rich.console import Console

from fleetlog.cli.replay_terminal import ProgressLine
from fleetlog.moos.alog import LineFormatter, format_banner
from fleetlog.replayer.clock import RealClock
from fleetlog.replayer.engine import Player
from fleetlog.replayer.inputs import open_input
from fleetlog.replayer.options import PlayOptions
from fleetlog.replayer.schedule import Schedule
from fleetlog.storage.readers import AlogReader
from fleetlog.transport.publisher import MoosPublisher
from fleetlog.transport.replay import ReplayLink
from fleetlog.transport.session import SessionOptions, open_session

ROOT = "fleet"
LOGSTART = 1_800_000_000.0


def write_alog(path: Path, offsets: list[float]) -> None:
    """Write an alog with one entry per offset, cycling through 4 variables."""
    fmt = LineFormatter()
    with path.open("w", encoding="utf-8") as out:
        out.write(format_banner(f"./{path.stem}/{path.name}", LOGSTART, "Thu Jan  1 00:00:00 1970"))
        for i, offset in enumerate(offsets):
            kind = i % 4
            if kind == 0:
                out.write(fmt.double(offset, "NAV_X", "pNav", i * 0.25))
            elif kind == 1:
                out.write(fmt.double(offset, "NAV_Y", "pNav", -i * 0.5))
            elif kind == 2:
                out.write(fmt.string(offset, "DEPLOY", "pHelmIvP:HELM_VAR_INIT", "true"))
            else:
                report = (
                    f"NAME=alpha,X={i * 0.1:.1f},Y=-4.5,SPD=1.2,HDG=90,TIME={LOGSTART + offset}"
                )
                out.write(fmt.string(offset, "NODE_REPORT_LOCAL", "pNodeReporter", report))


def measure_parse(path: Path) -> float:
    start = time.perf_counter()
    with AlogReader(path) as reader:
        count = sum(1 for _ in reader.entries())
    return count / (time.perf_counter() - start)


def measure_schedule(path: Path) -> float:
    source = open_input(path, VEHICLE)
    try:
        start = time.perf_counter()
        count = sum(1 for _ in Schedule([source]))
        return count / (time.perf_counter() - start)
    finally:
        source.close()


def counter(n: int) -> tuple[Helper, str]:
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    helper = Helper("counter", ["--listen", endpoint, "-n", str(n)])
    helper.read()  # ready
    return helper, endpoint


def wait_subscribed(link: ReplayLink) -> None:
    missing = link.wait_for_subscribers(10.0)
    if missing:
        raise RuntimeError(f"the counter never subscribed: {missing}")
    time.sleep(0.05)


def measure_bare(path: Path, n: int, cpus: list[float]) -> float:
    with AlogReader(path) as reader:
        values = [(e.key, e.value) for e in reader.entries() if isinstance(e.value, float | str)]
    helper, endpoint = counter(n)
    try:
        session = open_session(SessionOptions(connect=(endpoint,), multicast_scouting=False))
        try:
            link = ReplayLink(session, ROOT, [VEHICLE])
            wait_subscribed(link)
            pub = MoosPublisher(session, ROOT, VEHICLE, "bench")
            publish = pub.publish
            start, cpu = time.time(), time.thread_time()
            for key, value in values:
                publish(key, value)
            cpus.append(time.thread_time() - cpu)
            done = helper.read()
            pub.close()
            link.close()
        finally:
            session.close()
    finally:
        helper.finish()
    return n / (float(done["last"]) - start)


def measure_replay(path: Path, n: int, cpus: list[float]) -> float:
    helper, endpoint = counter(n)
    source = open_input(path, VEHICLE)
    try:
        session = open_session(SessionOptions(connect=(endpoint,), multicast_scouting=False))
        try:
            link = ReplayLink(session, ROOT, [VEHICLE])
            wait_subscribed(link)
            player = Player(
                [source],
                link.publish,
                RealClock(),
                PlayOptions(rate=None, db_time=False),
                senders=link.sender,
            )
            start, cpu = time.time(), time.thread_time()
            summary = player.run()
            cpus.append(time.thread_time() - cpu)
            done = helper.read()
            assert summary.published == n, summary.lines()
            link.close()
        finally:
            session.close()
    finally:
        source.close()
        helper.finish()
    return n / (float(done["last"]) - start)


def timing_offsets(seconds: float, seed: int = 7) -> list[float]:
    """Entries 0.2-5 ms apart, in bursts and gaps, for ``seconds`` of log."""
    rng = random.Random(seed)
    offsets: list[float] = []
    t = 1.0
    while t < 1.0 + seconds:
        t += rng.choice((0.0002, 0.0005, 0.001, 0.002, 0.005))
        offsets.append(round(t, 5))
    return offsets


def measure_timing(path: Path, n: int, clock: RealClock, display: bool) -> tuple[float, ...]:
    helper, endpoint = counter(n)
    source = open_input(path, VEHICLE)
    try:
        session = open_session(SessionOptions(connect=(endpoint,), multicast_scouting=False))
        try:
            link = ReplayLink(session, ROOT, [VEHICLE])
            wait_subscribed(link)
            options = PlayOptions(rate=1.0, db_time=False)
            player = Player([source], link.publish, clock, options, link.prepare, link.sender)
            if display:
                console = Console(file=io.StringIO(), force_terminal=True, width=120)
                with ProgressLine(player.status, console, keys=True) as line:
                    player.idle_hooks.append(line.refresh)
                    summary = player.run()
            else:
                summary = player.run()
            helper.read()
            link.close()
        finally:
            session.close()
    finally:
        source.close()
        helper.finish()
    timing = summary.timing
    p50, p99 = timing.percentile(50), timing.percentile(99)
    assert p50 is not None
    assert p99 is not None
    return p50 * 1e3, p99 * 1e3, timing.max * 1e3


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("-n", type=int, default=200_000, help="entries for the throughput runs")
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--timing-seconds", type=float, default=3.0)
    parser.add_argument("--only", choices=("throughput", "timing"), help="run one part only")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        if args.only != "timing":
            throughput(Path(tmp), args.n, args.rounds)
        if args.only != "throughput":
            timing(Path(tmp), args.timing_seconds)


def throughput(tmp: Path, n: int, rounds: int) -> None:
    big = tmp / "big.alog"
    write_alog(big, [1.0 + i * 0.001 for i in range(n)])
    rates: dict[str, list[float]] = {k: [] for k in ("parse", "schedule", "bare", "replay")}
    cpu_ratios: list[float] = []
    cpus: list[float] = []
    for _ in range(rounds):
        rates["parse"].append(measure_parse(big))
        rates["schedule"].append(measure_schedule(big))
        rates["bare"].append(measure_bare(big, n, cpus))
        rates["replay"].append(measure_replay(big, n, cpus))
        cpu_ratios.append(cpus[-2] / cpus[-1])
    print(f"replay throughput, {n:,} entries, {rounds} rounds (load {loadavg()})")
    labels = {
        "parse": "(a) parse only (AlogReader)",
        "schedule": "(b) schedule (parse+sort+dedupe)",
        "bare": "(c) bare MoosPublisher put loop",
        "replay": "(d) replay --fast (parse+publish)",
    }
    for key, label in labels.items():
        print(f"  {label:36s} {spread(rates[key])} entries/s")
    for other in ("parse", "bare"):
        ratios = [r / o for r, o in zip(rates["replay"], rates[other], strict=True)]
        print(f"  ratio replay / {other:5s}              {spread(ratios, '{:.2f}')}")
    # The publishing thread's CPU seconds, the bare put loop's over the player's run:
    # what the wall ratio would be if that thread had a core of its own, as on a quiet
    # machine; it holds when the shared machine is loaded and the wall ratio does not.
    print(f"  cpu ratio bare / replay (its thread) {spread(cpu_ratios, '{:.2f}')}")


def timing(tmp: Path, seconds: float) -> None:
    timed = tmp / "timed.alog"
    offsets = timing_offsets(seconds)
    write_alog(timed, offsets)
    print(
        f"1x timing, {len(offsets):,} entries over {seconds:g} s, ms after due (p50/p99/max)"
        f" (load {loadavg()})"
    )
    variants = [
        ("sleep only (baseline)", RealClock(spin_margin=0.0), False),
        ("sleep + 1 ms spin", RealClock(), False),
        ("sleep + spin, progress line on", RealClock(), True),
    ]
    results = {}
    for label, clock, display in variants:
        p50, p99, worst = measure_timing(timed, len(offsets), clock, display)
        results[label] = p99
        print(f"  {label:32s} p50 {p50:.3f}  p99 {p99:.3f}  max {worst:.3f}")
    base = results["sleep only (baseline)"]
    spin = results["sleep + 1 ms spin"]
    print(f"  p99 ratio spin / sleep-only       {spin / base:.2f}  (target: p99 < 2 ms)")


if __name__ == "__main__":
    main()
