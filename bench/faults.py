"""Crashes and overload, measured: what a SIGKILL loses, and whether a backlog changes times.

1. **Loss-free rate** of ``fleetlog record`` here and now: a full-speed BLOCK publisher (a
   helper process, fleetlog's ``MoosPublisher``) for a few seconds; the recorder's own
   counters give its write rate (``logged`` per second), with ``lost`` 0.
2. **SIGKILL at random moments** for plain, gzip and zstd logs, at offered rates of half the
   loss-free rate, 0.9 of it (paced) and full speed (unpaced: above what it takes). After
   each kill the alog is read back (cut tails included) and compared with what the publisher
   stamped:
   * *loss window*: how long before the kill the first sample missing from the disk was
     published (the issue's bound: under 1 s at any rate up to the loss-free rate);
   * *buffered*: what the recorder had taken in and not written, from its own counters (the
     last status before the kill: ``received``, ``logged`` per second, ``queue``): at most
     ``received + rate × (kill − status) + queue − lines on disk``, in seconds of its write
     rate (the bound above the loss-free rate: 1 s). Socket buffers hold samples too: at full
     speed the loss window also counts what the kernel held, which is not the recorder's.
3. **Overload at 3× the loss-free rate**: samples stamped on an offered schedule three times
   faster than the recorder takes them (BLOCK holds the publisher back, so the stamps fall
   further and further behind), published until they are ``--behind`` seconds (8) behind,
   well past pLogger's 5 s; then every line's time is checked against its stamp, with
   ``skewed`` and ``lost`` 0.

    python bench/faults.py                    # 3 kills per case, overload until 8 s behind
    python bench/faults.py --kills 5 --behind 10 --skip-kills

The machine is shared: the load average is printed before and after.
"""

from __future__ import annotations

import argparse
import json
import random
import signal
import statistics
import sys
import tempfile
import threading
import time
from array import array
from pathlib import Path
from typing import Any

from benchlib import Helper, free_port, loadavg

HERE = Path(__file__).resolve()
VEHICLE = "bench"
MISSION = (
    "ProcessConfig = pLogger\n{{\n  Path = ./\n  WildcardLogging = true\n"
    "  CompressAlogs = {c}\n}}\n"
)


# ------------------------------------------------------------------------------------------
# The publisher (a helper process: ``python bench/faults.py pub ...``)


def pub_main(argv: list[str]) -> int:
    from fleetlog.transport.bus import wait_for_subscriber
    from fleetlog.transport.publisher import MoosPublisher
    from fleetlog.transport.session import SessionOptions, open_session
    from fleetlog.wire.keys import var_key

    parser = argparse.ArgumentParser()
    parser.add_argument("--connect", required=True)
    parser.add_argument("--rate", type=float, default=0.0, help="paced per second; 0: full speed")
    parser.add_argument("--offered", type=float, default=0.0, help="stamp schedule; 0: real time")
    parser.add_argument("-n", type=int, default=10**9)
    parser.add_argument("--behind", type=float, default=0.0, help="stop once stamps lag this")
    parser.add_argument("--stamps", required=True)
    args = parser.parse_args(argv)
    session = open_session(SessionOptions(connect=(args.connect,), multicast_scouting=False))
    pub = MoosPublisher(session, "fleet", VEHICLE, "iBench")
    print(
        json.dumps(
            {
                "event": "ready",
                "sub": wait_for_subscriber(session, var_key("fleet", VEHICLE, "SEQ"), 15.0),
            }
        ),
        flush=True,
    )
    stop = threading.Event()

    def watch() -> None:
        for line in sys.stdin:
            if line.strip() in ("stop", "exit"):
                break
        stop.set()

    sys.stdin.readline()  # go
    threading.Thread(target=watch, daemon=True).start()
    stamps = array("d")
    now = time.time
    t0 = now()
    i = 0
    while i < args.n and not stop.is_set():
        if args.rate:
            ahead = t0 + i / args.rate - now()
            if ahead > 0:
                time.sleep(min(ahead, 0.001))
                continue
        stamp = t0 + i / args.offered if args.offered else now()
        if args.behind and not i & 1023 and now() - stamp >= args.behind:
            break
        pub.publish("SEQ", float(i), time=stamp)
        stamps.append(stamp)
        i += 1
    Path(args.stamps).write_bytes(stamps.tobytes())
    print(json.dumps({"event": "done", "n": i, "t0": t0, "t1": now()}), flush=True)
    stop.wait()
    pub.close()
    session.close()
    return 0


# ------------------------------------------------------------------------------------------
# The parent


class Recorder:
    def __init__(self, workdir: Path, port: int, compress: str) -> None:
        import subprocess

        (workdir / "m.moos").write_text(MISSION.format(c=compress))
        self.workdir = workdir
        self.proc = subprocess.Popen(
            [
                sys.executable,
                "-m",
                "fleetlog",
                "record",
                "m.moos",
                "--vehicle",
                VEHICLE,
                "--no-serve",
                "-l",
                f"tcp/127.0.0.1:{port}",
                "--no-multicast-scouting",
            ],
            cwd=workdir,
            stderr=subprocess.PIPE,
            stdout=subprocess.DEVNULL,
            text=True,
        )
        assert self.proc.stderr is not None
        while "recording" not in (line := self.proc.stderr.readline()):
            if not line:
                raise RuntimeError("the recorder did not start")

    def alog(self) -> Path:
        return next(p for p in self.workdir.rglob("*.alog*") if ".xlog" not in p.name)

    def kill(self) -> None:
        self.proc.send_signal(signal.SIGKILL)
        self.proc.wait()
        assert self.proc.stderr is not None
        self.proc.stderr.close()

    def stop(self) -> None:
        self.proc.send_signal(signal.SIGINT)
        self.proc.wait(60)
        assert self.proc.stderr is not None
        self.proc.stderr.close()


class Status:
    """Polls the recorder's status queryable."""

    def __init__(self, port: int) -> None:
        from fleetlog.transport.session import SessionOptions, open_session

        self.session = open_session(
            SessionOptions(connect=(f"tcp/127.0.0.1:{port}",), multicast_scouting=False)
        )

    def get(self) -> tuple[float, dict[str, Any]] | None:
        from fleetlog.transport.queries import start_query

        replies = list(start_query(self.session, f"fleet/{VEHICLE}/@fleetlog/status", timeout=5.0))
        if not replies:
            return None
        return time.time(), json.loads(replies[0].payload)

    def close(self) -> None:
        self.session.close()


def read_alog(path: Path) -> tuple[dict[int, float], int]:
    """Return SEQ value → written time, and how many entries the alog holds in all."""
    from fleetlog.storage.readers import AlogReader

    seqs: dict[int, float] = {}
    total = 0
    with AlogReader(path, errors="skip") as reader:
        for record in reader.records():
            if record.entry.key == "PLOGGER_GAP":
                continue
            total += 1
            if record.entry.key == "SEQ":
                seqs[int(record.entry.value)] = record.time  # type: ignore[arg-type]
    return seqs, total


def publisher(
    port: int,
    stamps: Path,
    *,
    rate: float = 0.0,
    offered: float = 0.0,
    n: int = 10**9,
    behind: float = 0.0,
) -> Helper:
    args = ["--connect", f"tcp/127.0.0.1:{port}", "--stamps", str(stamps), "-n", str(n)]
    if rate:
        args += ["--rate", str(rate)]
    if offered:
        args += ["--offered", str(offered)]
    if behind:
        args += ["--behind", str(behind)]
    helper = Helper("pub", args, script=HERE)
    helper.read()
    return helper


def loss_free_rate(tmp: Path) -> float:
    """The recorder's write rate at full speed (BLOCK: nothing dropped), from its counters."""
    work = tmp / "rate"
    work.mkdir()
    port = free_port()
    rec = Recorder(work, port, "false")
    status = Status(port)
    pub = publisher(port, work / "stamps.bin")
    pub.send("go")
    time.sleep(1.5)
    first = status.get()
    time.sleep(3.0)
    last = status.get()
    pub.send("stop")
    pub.read()
    pub.finish()
    rec.stop()
    status.close()
    assert first
    assert last
    assert last[1]["lost"] == 0
    return (last[1]["logged"] - first[1]["logged"]) / (last[0] - first[0])


def one_kill(tmp: Path, compress: str, rate: float, label: str, k: int) -> dict[str, float]:
    work = tmp / f"{compress}-{label}-{k}"
    work.mkdir()
    port = free_port()
    rec = Recorder(work, port, compress)
    status = Status(port)
    stamps_file = work / "stamps.bin"
    pub = publisher(port, stamps_file, rate=rate)
    pub.send("go")
    deadline = time.monotonic() + random.uniform(2.0, 4.0)
    history: list[tuple[float, dict[str, Any]]] = []
    while time.monotonic() < deadline:
        got = status.get()
        if got:
            history.append(got)
        time.sleep(0.02)
    last = status.get() or history[-1]
    killed = time.time()
    rec.kill()
    pub.send("stop")
    pub.read()
    pub.finish()
    status.close()
    stamps = array("d")
    stamps.frombytes(stamps_file.read_bytes())
    seqs, total = read_alog(rec.alog())
    missing = next((i for i in range(len(stamps)) if i not in seqs), None)
    window = killed - stamps[missing] if missing is not None else 0.0
    # the write rate over the last second of statuses
    t_s, body = last
    older = [h for h in history if h[0] <= t_s - 1.0] or history[:1]
    t_o, body_o = older[-1]
    write_rate = (body["logged"] - body_o["logged"]) / max(t_s - t_o, 1e-3)
    taken_bound = body["received"] + write_rate * (killed - t_s) + body["queue"]
    buffered = max(0.0, taken_bound - total) / max(write_rate, 1.0)
    return {"window": window, "buffered": buffered, "rate": write_rate, "published": len(stamps)}


def overload(tmp: Path, lf: float, behind: float) -> dict[str, Any]:
    work = tmp / "overload"
    work.mkdir()
    port = free_port()
    rec = Recorder(work, port, "zstd")
    status = Status(port)
    offered = 3.0 * lf
    stamps_file = work / "stamps.bin"
    pub = publisher(port, stamps_file, offered=offered, behind=behind)
    pub.send("go")
    done = pub.read(timeout=600)
    n = int(done["n"])
    worst_lag = 0.0
    while True:
        got = status.get()
        if got:
            worst_lag = max(worst_lag, got[1]["max_lag"])
            if got[1]["received"] >= n:
                break
        time.sleep(0.2)
    body = got[1] if got else {}
    pub.send("stop")
    pub.finish()
    rec.stop()
    status.close()
    stamps = array("d")
    stamps.frombytes(stamps_file.read_bytes())
    seqs, _ = read_alog(rec.alog())
    errors = [abs(seqs[i] - stamps[i]) for i in range(len(stamps)) if i in seqs]
    return {
        "offered": offered,
        "n": n,
        "published_in": done["t1"] - done["t0"],
        "taken_rate": n / (done["t1"] - done["t0"]),
        "behind_at_end": (done["t1"] - done["t0"]) - (n / offered),
        "on_disk": len(seqs),
        "worst_time_error": max(errors) if errors else float("nan"),
        "skewed": body.get("skewed"),
        "lost": body.get("lost"),
        "max_lag": worst_lag,
    }


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--kills", type=int, default=3, help="kills per compression and rate")
    parser.add_argument(
        "--behind", type=float, default=8.0, help="overload until stamps lag this (s)"
    )
    parser.add_argument("--skip-kills", action="store_true")
    args = parser.parse_args()
    print(f"load before: {loadavg()}", flush=True)
    with tempfile.TemporaryDirectory() as tmp_name:
        tmp = Path(tmp_name)
        lf = loss_free_rate(tmp)
        print(
            f"loss-free rate (recorder's write rate at full speed, lost 0): {lf:,.0f}/s", flush=True
        )
        if not args.skip_kills:
            print(
                "\n| log | offered | kills | worst loss window"
                " | worst buffered (s of write rate) | published per run |"
            )
            print("|---|---|---|---|---|---|")
            for compress in ("false", "gzip", "zstd"):
                for label, rate in (("0.5×", 0.5 * lf), ("0.9×", 0.9 * lf), ("full", 0.0)):
                    runs = [one_kill(tmp, compress, rate, label, k) for k in range(args.kills)]
                    name = {"false": "plain", "gzip": "gzip", "zstd": "zstd"}[compress]
                    window = max(r["window"] for r in runs) * 1000
                    buffered = max(r["buffered"] for r in runs)
                    published = statistics.median(r["published"] for r in runs)
                    print(
                        f"| {name} | {label} | {len(runs)} | {window:.0f} ms "
                        f"| {buffered:.2f} s | {published:,.0f} |",
                        flush=True,
                    )
        result = overload(tmp, lf, args.behind)
        print(f"\noverload: {json.dumps(result, indent=1)}")
    print(f"load after: {loadavg()}")
    return 0


if __name__ == "__main__":
    if len(sys.argv) > 1 and sys.argv[1] == "pub":
        sys.exit(pub_main(sys.argv[2:]))
    sys.exit(main())
