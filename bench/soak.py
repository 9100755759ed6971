"""Soak: ``fleetlog record`` for minutes under a steady rate, restarts, shore work and garbage.

What runs at once, against one recorder (a subprocess, plain alogs under ``./logs``):

* a publisher helper putting ``SEQ`` = 0, 1, 2, … at ``--rate`` per second (BLOCK);
* a ``LOGGER_RESTART`` every ``--restart`` seconds (a new session each time);
* ``fleetlog fetch --latest`` in a loop (the session being written: fetched as far as it
  goes) and ``fleetlog query bench SEQ --limit 1000`` in a loop (remote grep);
* a hostile peer: random bytes on random variable names (valid, and with broken escapes),
  payloads that lie about their encoding, garbage attachments, garbage control requests
  and status parameters, about 300 a second.

Every 10 s the recorder's RSS (``/proc``) and status are sampled. At the end the recorder
is stopped and the sessions are read back: every ``SEQ`` published must be on disk exactly
once (across sessions), every session ``closed``, every loss marked ``unreadable`` (the
garbage), and RSS flat: the median of the last minute against the second minute's.

    python bench/soak.py                 # 10 minutes, 20,000 SEQ/s, a restart a minute
    python bench/soak.py --minutes 2 --rate 5000 --restart 30
"""

from __future__ import annotations

import argparse
import json
import random
import shutil
import signal
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from array import array
from pathlib import Path
from typing import Any

from benchlib import Helper, free_port, loadavg

HERE = Path(__file__).resolve().parent
VEHICLE = "bench"
STATUS_KEYS = ("received", "logged", "lost", "garbled", "skewed", "write_errors", "max_lag")
MISSION = "ProcessConfig = pLogger\n{\n  Path = ./logs\n  WildcardLogging = true\n}\n"


#: the parts of the resident set sampled: the whole, the heap's (anonymous) and the mapped
#: files' (the interpreter's and the libraries' code, which grows as code paths are first run)
RSS_PARTS = ("VmRSS", "RssAnon", "RssFile")


def rss_kb(pid: int) -> dict[str, int]:
    """Return the process's resident set and its parts, in KiB (``/proc/PID/status``)."""
    parts = dict.fromkeys(RSS_PARTS, 0)
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        name, _, value = line.partition(":")
        if name in parts:
            parts[name] = int(value.split()[0])
    return parts


def per_minute(samples: list[tuple[float, dict[str, int], Any]], part: str) -> list[float]:
    """Return the median of ``part`` in each minute of the run, in MiB."""
    minutes: dict[int, list[int]] = {}
    for t, kb, _ in samples:
        minutes.setdefault(int(t // 60), []).append(kb[part])
    return [round(statistics.median(v) / 1024, 1) for _, v in sorted(minutes.items())]


#: the first failures of each shore loop: (seconds into the soak, exit code, last stderr line)
FAILURES: dict[str, list[tuple[float, int, str]]] = {}
STARTED = time.monotonic()


def cli(*args: str, endpoint: str, cwd: Path, timeout: float = 120.0) -> int:
    done = subprocess.run(
        [sys.executable, "-m", "fleetlog", *args, "-e", endpoint, "--no-multicast-scouting"],
        cwd=cwd,
        capture_output=True,
        timeout=timeout,
        check=False,
    )
    if done.returncode:
        seen = FAILURES.setdefault(args[0], [])
        if len(seen) < 10:
            lines = done.stderr.decode("utf-8", "replace").strip().splitlines() or ["(nothing)"]
            seen.append((round(time.monotonic() - STARTED, 1), done.returncode, lines[-1][:300]))
    return done.returncode


class Loop(threading.Thread):
    """Runs ``work`` again and again until stopped; counts runs and failures."""

    def __init__(self, work: Any) -> None:
        super().__init__(daemon=True)
        self.work = work
        self.halt = threading.Event()
        self.runs = 0
        self.failures = 0

    def run(self) -> None:
        while not self.halt.is_set():
            try:
                ok = self.work()
            except Exception:  # a soak keeps going; failures are counted
                ok = False
            self.runs += 1
            self.failures += 0 if ok else 1
            self.halt.wait(0.2)


def hostile(endpoint: str, halt: threading.Event, counts: dict[str, int]) -> None:
    """Garbage on the vehicle's keys and services, about 300 puts/queries a second."""
    import zenoh

    conf = zenoh.Config()
    conf.insert_json5("connect/endpoints", json.dumps([endpoint]))
    conf.insert_json5("scouting/multicast/enabled", "false")
    rng = random.Random(7)
    with zenoh.open(conf) as session:
        while not halt.is_set():
            for _ in range(30):
                kind = rng.randrange(6)
                name = "".join(rng.choice("ABCXYZ_%2F09") for _ in range(rng.randrange(1, 12)))
                key = f"fleet/{VEHICLE}/var/{name or 'X'}"
                payload = rng.randbytes(rng.randrange(0, 200))
                try:
                    if kind == 0:
                        session.put(key, payload)
                    elif kind == 1:
                        session.put(key, payload, encoding="text/plain;moos-double")
                    elif kind == 2:
                        session.put(key, b"1.5", attachment=rng.randbytes(20))
                    elif kind == 3:
                        session.put(f"fleet/{VEHICLE}/var/BAD%ZZ{rng.randrange(10**6)}", b"x")
                    elif kind == 4:
                        session.get(
                            f"fleet/{VEHICLE}/@fleetlog/control", payload=payload, timeout=1.0
                        )
                    else:
                        session.get(
                            f"fleet/{VEHICLE}/@fleetlog/status?{payload.hex()}", timeout=1.0
                        )
                    counts[str(kind)] = counts.get(str(kind), 0) + 1
                except zenoh.ZError:
                    counts["refused"] = counts.get("refused", 0) + 1
            halt.wait(0.1)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--minutes", type=float, default=10.0)
    parser.add_argument("--rate", type=float, default=20_000.0)
    parser.add_argument("--restart", type=float, default=60.0)
    parser.add_argument("--no-fetch", action="store_true", help="(to attribute memory)")
    parser.add_argument("--no-grep", action="store_true", help="(to attribute memory)")
    parser.add_argument("--no-garbage", action="store_true", help="(to attribute memory)")
    args = parser.parse_args()
    from fleetlog.api import Vehicle
    from fleetlog.storage.readers import AlogReader
    from fleetlog.transport.queries import start_query
    from fleetlog.transport.session import SessionOptions, open_session
    from fleetlog.wire.session_meta import META_NAME, SessionMeta

    print(f"load before: {loadavg()}", flush=True)
    tmp = Path(tempfile.mkdtemp(prefix="fleetlog-soak-"))
    try:
        (tmp / "m.moos").write_text(MISSION)
        (tmp / "logs").mkdir()
        port = free_port()
        endpoint = f"tcp/127.0.0.1:{port}"
        rec = subprocess.Popen(
            [sys.executable, "-m", "fleetlog", "record", "m.moos", "--vehicle", VEHICLE,
             "-l", endpoint, "--no-multicast-scouting"],
            cwd=tmp, stderr=subprocess.PIPE, stdout=subprocess.DEVNULL, text=True,
        )  # fmt: skip
        assert rec.stderr is not None
        while "recording" not in (line := rec.stderr.readline()):
            if not line:
                raise RuntimeError("the recorder did not start")
        err_tail: list[str] = []
        stderr = rec.stderr
        threading.Thread(target=lambda: err_tail.extend(stderr), daemon=True).start()
        stamps = tmp / "stamps.bin"
        pub = Helper(
            "pub",
            ["--connect", endpoint, "--stamps", str(stamps), "--rate", str(args.rate)],
            script=HERE / "faults.py",
        )
        pub.read()
        opts = SessionOptions(connect=(endpoint,), multicast_scouting=False)
        shore = open_session(opts)
        ops = Vehicle(VEHICLE, source="iSoak", session=shore)
        out = tmp / "fetched"

        def fetch() -> bool:
            shutil.rmtree(out, ignore_errors=True)
            return (
                cli("fetch", VEHICLE, "--latest", "-o", str(out), endpoint=endpoint, cwd=tmp) == 0
            )

        def grep() -> bool:
            return cli("query", VEHICLE, "SEQ", "--limit", "1000", endpoint=endpoint, cwd=tmp) == 0

        loops = [Loop(fetch), Loop(grep)]
        if args.no_fetch:
            loops[0].halt.set()
        if args.no_grep:
            loops[1].halt.set()
        garbage: dict[str, int] = {}
        halt = threading.Event()
        bad = threading.Thread(target=hostile, args=(endpoint, halt, garbage), daemon=True)
        pub.send("go")
        for loop in loops:
            loop.start()
        if not args.no_garbage:
            bad.start()
        samples: list[tuple[float, dict[str, int], dict[str, Any]]] = []
        started = time.monotonic()
        next_restart = started + args.restart
        end = started + args.minutes * 60
        while (now := time.monotonic()) < end:
            if now >= next_restart:
                ops.publish("LOGGER_RESTART", "soak")
                next_restart += args.restart
            replies = list(start_query(shore, f"fleet/{VEHICLE}/@fleetlog/status", timeout=5.0))
            body: dict[str, Any] = {}
            for reply in replies:  # an error reply (busy, at load 25) is not a status
                try:
                    body = json.loads(reply.payload)
                    break
                except ValueError:
                    continue
            samples.append((now - started, rss_kb(rec.pid), body))
            print(
                f"{now - started:6.0f} s  rss {samples[-1][1]['VmRSS'] / 1024:6.1f} MiB (anon "
                f"{samples[-1][1]['RssAnon'] / 1024:.1f})  received "
                f"{body.get('received', '?')}  lost {body.get('lost', '?')}  sessions "
                f"{body.get('sessions', '?')}  max_lag {body.get('max_lag', 0):.3f} s",
                flush=True,
            )
            time.sleep(min(10.0, max(0.0, end - time.monotonic())))
        pub.send("stop")
        done = pub.read()
        time.sleep(1.0)  # the last samples reach the recorder
        halt.set()
        for loop in loops:
            loop.halt.set()
        for loop in loops:
            loop.join(180)
        if bad.is_alive():
            bad.join(30)
        ops.close()
        shore.close()
        pub.finish()
        rec.send_signal(signal.SIGINT)
        rec.wait(120)

        published = array("d")
        published.frombytes(stamps.read_bytes())
        seen = bytearray(len(published))
        duplicates = 0
        states: dict[str, int] = {}
        reasons: dict[str, int] = {}
        sessions = sorted(p for p in (tmp / "logs").iterdir() if p.is_dir())
        for session in sessions:
            meta = SessionMeta.from_bytes((session / META_NAME).read_bytes())
            states[meta.state] = states.get(meta.state, 0) + 1
            for gap in meta.gaps:
                reasons[gap.reason] = reasons.get(gap.reason, 0) + (gap.lost or 0)
            with AlogReader(session / f"{session.name}.alog", errors="skip") as reader:
                for record in reader.records():
                    if record.entry.key == "SEQ":
                        # The first token: a garbage name with bytes readers do not take
                        # for a key makes its line read as the previous value's next line.
                        i = int(float(str(record.entry.value).split()[0]))
                        duplicates += seen[i]
                        seen[i] = 1
        missing = len(published) - sum(seen)
        # Where the missing ones are: runs of consecutive SEQ values (first, how many, seconds
        # before the end of publishing), so a cut at the end tells itself from holes.
        holes: list[tuple[int, int, float]] = []
        i = seen.find(0)
        while i != -1:
            j = seen.find(1, i)
            j = len(seen) if j == -1 else j
            holes.append((i, j - i, round(published[-1] - published[i], 3)))
            i = seen.find(0, j)
        # RSS flat: the median of the last minute against the second minute's, for the whole
        # resident set and for its anonymous part (the heap; the mapped files' part is code).
        minute2 = [kb for t, kb, _ in samples if 60 <= t < 120] or [samples[0][1]]
        last = [kb for t, kb, _ in samples if t >= samples[-1][0] - 60]

        def ratio(part: str) -> float:
            return statistics.median(k[part] for k in last) / statistics.median(
                k[part] for k in minute2
            )

        final = samples[-1][2]
        result = {
            "minutes": args.minutes,
            "rate": args.rate,
            "published": len(published),
            "publish_seconds": done["t1"] - done["t0"],
            "missing": missing,
            "duplicates": duplicates,
            "missing_runs": len(holes),
            "missing_first_runs": holes[:5],
            "missing_last_runs": holes[-5:],
            "sessions": len(sessions),
            "states": states,
            "gap_reasons": reasons,
            "rss_minute2_mib": statistics.median(k["VmRSS"] for k in minute2) / 1024,
            "rss_last_minute_mib": statistics.median(k["VmRSS"] for k in last) / 1024,
            "rss_ratio": ratio("VmRSS"),
            "rss_anon_ratio": ratio("RssAnon"),
            "rss_per_minute_mib": {part: per_minute(samples, part) for part in RSS_PARTS},
            "fetch_runs": loops[0].runs,
            "fetch_failed": loops[0].failures,
            "grep_runs": loops[1].runs,
            "grep_failed": loops[1].failures,
            "first_failures": FAILURES,
            "garbage": garbage,
            "final_status": {k: final.get(k) for k in STATUS_KEYS},
        }
        print(json.dumps(result, indent=1))
        print(f"load after: {loadavg()}")
        print(f"recorder stderr (last lines): {''.join(err_tail[-5:])!r}")
        ok = missing == 0 and duplicates == 0 and set(states) == {"closed"}
        ok &= set(reasons) <= {"unreadable"}
        return 0 if ok else 1
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    sys.exit(main())
