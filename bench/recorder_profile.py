"""Where the recorder's time goes per sample, on real Zenoh samples, in one process.

Publishes N doubles on a few keys with fleetlog's ``MoosPublisher`` into a FIFO subscriber
of a second session in this process (capacity N, so nothing blocks), then times each stage
of the recorder's hot path on those samples, in isolation, as this thread's CPU time
(``time.thread_time``: other processes on the machine inflate wall time, not this), best
of ``--repeat``:

* recv: draining the filled FIFO with ``try_recv`` (what the service loop pays per sample);
* decode: ``SampleDecoder.decode`` (key → name, payload, attachment);
* lane: the drain's way, :class:`~fleetlog.recorder.lane.Lane` (the common samples formatted
  straight into their line, 32 at a time, with the flushes the drain would make);
* handle: ``Recorder.handle`` on the decoded messages (default config: wildcard logging,
  writing a real session in a temporary directory), including LineFormatter, and the
  flushes the service would make (every 5 ms);
* format: ``LineFormatter.double`` alone;
* publish: ``MoosPublisher.publish`` into a session with no subscriber (the publisher's
  own cost, which bounds the bare-subscriber figure of recorder_rate.py).

``--profile`` adds a cProfile of the lane (top functions by own time).

``--service`` instead runs a whole :class:`RecorderService` (default configuration) in a
thread of this process, fed by a publisher process at full speed (``--raw``: pre-encoded
zenoh puts), and reports the CPU its thread and Zenoh's threads spent per sample (from
``/proc``), the loop's overhead beyond decode + handle, and with ``--profile`` a cProfile of
the service thread.

    python bench/recorder_profile.py -n 200000 --repeat 5 --profile
    python bench/recorder_profile.py --service --raw -n 200000 --profile
"""

from __future__ import annotations

import argparse
import cProfile
import os
import pstats
import statistics
import sys
import tempfile
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import zenoh
from benchlib import ROOT, VEHICLE, Helper, free_port, key_names, loadavg, matching

from fleetlog.moos.alog import LineFormatter
from fleetlog.moos.mission import LoggerConfig
from fleetlog.recorder.engine import Recorder
from fleetlog.recorder.lane import Lane
from fleetlog.recorder.service import RecorderService, ServiceOptions
from fleetlog.transport.bus import SampleDecoder
from fleetlog.transport.publisher import MoosPublisher
from fleetlog.transport.session import SessionOptions, open_session
from fleetlog.wire.keys import var_key
from fleetlog.wire.message import attachment_fields


def collect(n: int, keys: int) -> tuple[list[Any], list[float]]:
    """Publish N samples into an in-process FIFO; return them and the drain time per run."""
    port = free_port()
    ep = f"tcp/127.0.0.1:{port}"
    sub_s = open_session(SessionOptions(listen=(ep,), multicast_scouting=False))
    pub_s = open_session(SessionOptions(connect=(ep,), multicast_scouting=False))
    names = key_names(keys)
    samples: list[Any] = []
    drains: list[float] = []
    try:
        sub = sub_s.declare_subscriber(
            f"{ROOT}/{VEHICLE}/var/*", zenoh.handlers.FifoChannel(n + 16)
        )
        for name in names:
            probe = pub_s.declare_publisher(var_key(ROOT, VEHICLE, name))
            while not matching(probe):
                time.sleep(0.002)
            probe.undeclare()
        pub = MoosPublisher(pub_s, ROOT, VEHICLE, "bench")
        for i in range(n):
            pub.publish(names[i % keys], float(i // keys))
        # Wait until everything is queued, then time the drain alone.
        deadline = time.monotonic() + 30
        while time.monotonic() < deadline:
            time.sleep(0.2)
            got = sub.try_recv()
            if got is not None:
                samples.append(got)
                break
        time.sleep(1.0)
        try_recv = sub.try_recv
        start = time.thread_time()
        sample = try_recv()
        while sample is not None:
            samples.append(sample)
            sample = try_recv()
        drains.append((time.thread_time() - start) / max(1, len(samples) - 1) * 1e6)
        pub.close()
        sub.undeclare()
    finally:
        pub_s.close()
        sub_s.close()
    return samples, drains


def best(fn: Callable[[], int], repeat: int) -> tuple[float, list[float]]:
    """Run fn (which returns how many items it processed) repeat times; CPU µs per item."""
    per: list[float] = []
    for _ in range(repeat):
        start = time.thread_time()
        count = fn()
        per.append((time.thread_time() - start) / count * 1e6)
    return min(per), per


def thread_cpu() -> dict[int, tuple[str, float]]:
    """CPU seconds (user + system) of each thread of this process, by thread id."""
    tick = os.sysconf("SC_CLK_TCK")
    out: dict[int, tuple[str, float]] = {}
    for tid in os.listdir("/proc/self/task"):
        try:
            with open(f"/proc/self/task/{tid}/stat") as f:
                stat = f.read()
        except OSError:
            continue
        name = stat[stat.index("(") + 1 : stat.rindex(")")]
        fields = stat[stat.rindex(")") + 2 :].split()
        out[int(tid)] = (name, (int(fields[11]) + int(fields[12])) / tick)
    return out


def run_service(args: argparse.Namespace) -> int:
    """A RecorderService in a thread of this process, fed by a publisher process."""
    n, keys = args.n, args.keys
    port = free_port()
    prof = cProfile.Profile() if args.profile else None
    with tempfile.TemporaryDirectory(prefix="fleetlog-svc-") as tmp:
        options = ServiceOptions(
            vehicle=VEHICLE,
            root=ROOT,
            zenoh=SessionOptions(listen=(f"tcp/127.0.0.1:{port}",), multicast_scouting=False),
            cwd=Path(tmp),
        )
        service = RecorderService(LoggerConfig.default(), options)
        ids: list[int] = []

        def target() -> None:
            ids.append(threading.get_native_id())
            if prof is not None:
                prof.enable()
            try:
                service.run()
            finally:
                if prof is not None:
                    prof.disable()

        thread = threading.Thread(target=target, name="service")
        thread.start()
        service.ready.wait(30)
        args_pub = ["--connect", f"tcp/127.0.0.1:{port}", "-n", str(n), "--keys", str(keys)]
        args_pub += ["--rate", str(args.rate)]
        pub = Helper("publisher", [*args_pub, "--raw"] if args.raw else args_pub)
        try:
            pub.read()
            before = thread_cpu()
            pub.send("go")
            sent = pub.read()
            recorder = service.recorder
            assert recorder is not None
            deadline = time.monotonic() + 120
            while recorder.stats.logged < n + 1 and time.monotonic() < deadline:
                time.sleep(0.002)
            done = time.time()
            after = thread_cpu()
        finally:
            pub.finish()
            service.stop()
            thread.join(30)
    stats = recorder.stats
    print(
        f"service: {n / (done - sent['t0']):,.0f} samples/s, logged {stats.logged:,}, "
        f"lost {stats.lost} (load {loadavg()})"
    )
    print("CPU µs per sample, by thread of this process:")
    for tid, (name, cpu) in sorted(after.items()):
        used = cpu - before.get(tid, (name, 0.0))[1]
        label = "service loop" if ids and tid == ids[0] else name
        if used > 0.005:
            print(f"  {label:<20} {used / n * 1e6:6.2f}")
    if prof is not None:
        print()
        pstats.Stats(prof).sort_stats("tottime").print_stats(15)
    return 0


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("-n", type=int, default=200_000)
    parser.add_argument("--keys", type=int, default=4)
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--profile", action="store_true", help="cProfile the lane")
    parser.add_argument("--service", action="store_true", help="profile a RecorderService")
    parser.add_argument("--raw", action="store_true", help="--service: pre-encoded zenoh puts")
    parser.add_argument("--rate", type=float, default=0.0, help="--service: msg/s (0: flat out)")
    args = parser.parse_args()
    if args.service:
        return run_service(args)
    n: int = args.n
    keys: int = args.keys
    print(f"collecting {n:,} samples on {keys} keys (load {loadavg()})", flush=True)
    samples, drains = collect(n, keys)
    if len(samples) != n:
        print(f"only {len(samples)} of {n} samples arrived", file=sys.stderr)
        return 1
    prefix = f"{ROOT}/{VEHICLE}/var/"

    def run_decode() -> int:
        decode = SampleDecoder(prefix).decode
        for s in samples:
            decode(s)
        return len(samples)

    messages = [x.message for x in map(SampleDecoder(prefix).decode, samples) if x is not None]

    with tempfile.TemporaryDirectory(prefix="fleetlog-prof-") as tmp:
        posted: list[object] = []

        # The recorders' clock runs from just before the first sample was published, as a
        # recorder that was running then would see it (else every sample would be older than
        # LOGSTART: skewed, restamped, and never the lane's).
        first = attachment_fields(samples[0].attachment.to_bytes())[0]

        def make_recorder(index: int) -> Recorder:
            cwd = Path(tmp) / f"r{index}"
            cwd.mkdir()
            shift = time.time() - first + 0.001

            def clock() -> float:
                return time.time() - shift

            rec = Recorder(
                LoggerConfig.default(), vehicle=VEHICLE, publish=posted.append, cwd=cwd, clock=clock
            )
            rec.start()
            return rec

        counter = iter(range(1_000_000))

        # Both flush as the service's drain loop does under load: the deadline checked every
        # 32 samples, a flush once lines waited 5 ms.
        def run_handle() -> int:
            rec = make_recorder(next(counter))
            handle = rec.handle
            flush_due = rec.flush_due
            for i, m in enumerate(messages):
                handle(m)
                if not i & 31 and flush_due(0.005):
                    rec.flush()
            rec.stop()
            return len(messages)

        def run_decode_handle() -> int:
            rec = make_recorder(next(counter))
            decode = SampleDecoder(prefix).decode
            handle = rec.handle
            flush_due = rec.flush_due
            for i, s in enumerate(samples):
                incoming = decode(s)
                if incoming is not None:
                    handle(incoming.message, garbled=incoming.garbled)
                if not i & 31 and flush_due(0.005):
                    rec.flush()
            rec.stop()
            return len(samples)

        def run_lane() -> int:
            rec = make_recorder(next(counter))
            lane = Lane(rec, SampleDecoder(prefix), lambda info, sample: None)
            rest = iter(samples)

            def try_recv() -> Any:
                return next(rest, None)

            flush_due = rec.flush_due
            while True:
                first = next(rest, None)
                if first is None:
                    break
                if lane.pump(first, try_recv, 32) < 32:
                    break
                if flush_due(0.005):
                    rec.flush()
            rec.stop()
            assert lane.fast >= len(samples) - keys, "the lane did not take the samples"
            return len(samples)

        def run_format() -> int:
            fmt = LineFormatter()
            double = fmt.double
            names = key_names(keys)
            for i in range(n):
                double(1.5 + i * 1e-5, names[i % keys], "bench", float(i))
            return n

        def run_publish() -> int:
            ep = f"tcp/127.0.0.1:{free_port()}"
            with open_session(SessionOptions(listen=(ep,), multicast_scouting=False)) as s:
                pub = MoosPublisher(s, ROOT, VEHICLE, "bench")
                names = key_names(keys)
                count = min(n, 100_000)
                for i in range(count):
                    pub.publish(names[i % keys], float(i // keys))
                pub.close()
            return count

        stages = [
            ("decode", run_decode),
            ("handle (engine+format+write)", run_handle),
            ("decode + handle", run_decode_handle),
            ("lane (what the drain runs)", run_lane),
            ("format (LineFormatter.double)", run_format),
            ("publish (MoosPublisher, no sub)", run_publish),
        ]
        print(f"CPU µs per sample, best of {args.repeat} [all runs]:")
        print(f"  {'recv (try_recv drain)':<34} {statistics.median(drains):6.2f}")
        results: dict[str, float] = {}
        for label, fn in stages:
            low, per = best(fn, args.repeat)
            results[label] = low
            runs = " ".join(f"{x:.2f}" for x in per)
            print(f"  {label:<34} {low:6.2f}   [{runs}]", flush=True)
        total = statistics.median(drains) + results["decode + handle"]
        print(f"  {'recv + decode + handle':<34} {total:6.2f}  → ceiling {1e6 / total:,.0f}/s")
        total = statistics.median(drains) + results["lane (what the drain runs)"]
        print(f"  {'recv + lane':<34} {total:6.2f}  → ceiling {1e6 / total:,.0f}/s")

        if args.profile:
            prof = cProfile.Profile()
            prof.enable()
            run_lane()
            prof.disable()
            print()
            pstats.Stats(prof).sort_stats("tottime").print_stats(18)
    return 0


if __name__ == "__main__":
    sys.exit(main())
