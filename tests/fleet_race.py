"""Discovery in the default mode, measured: N recorders, embedded peers, multicast scouting.

Run by ``tests/shore/test_race.py`` with small counts, and by hand with the issue's::

    python tests/fleet_race.py --vehicles 10 --fleet-runs 50 --fetch-runs 20

It re-runs itself in a network namespace of its own (``tests/netns.py``) unless told it is
in one, starts N ``fleetlog record`` processes with no Zenoh option at all (the README's
default mode) under a key root of its own, then counts:

* ``naive``: a plain Zenoh liveliness query sent right after ``zenoh.open`` (the race the
  issue found, the baseline): how often it saw every vehicle;
* ``fleet``: how often ``fleetlog fleet --json`` listed every vehicle (and exited 0);
* ``fetch``: how often ``fleetlog fetch --all --latest`` fetched every vehicle (and exited 0);
* ``stopped``: with one recorder stopped, ``fetch --all --latest --expect ...`` must exit
  non-zero naming it.

It prints one JSON object on stdout.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent


def _fleetlog(*args: str) -> list[str]:
    return [sys.executable, "-m", "fleetlog", *args]


class Recorder:
    """A ``fleetlog record`` in the default mode; ready once it says it is recording."""

    def __init__(self, vehicle: str, root: str, cwd: Path, env: dict[str, str]) -> None:
        self.vehicle = vehicle
        cwd.mkdir(parents=True, exist_ok=True)
        self.proc = subprocess.Popen(
            _fleetlog("record", "--vehicle", vehicle, "--root", root),
            cwd=cwd,
            env=env,
            stdin=subprocess.DEVNULL,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE,
            text=True,
        )
        self.ready = threading.Event()
        self.lines: list[str] = []
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        assert self.proc.stderr is not None
        for line in self.proc.stderr:
            self.lines.append(line)
            if "recording vehicle" in line:
                self.ready.set()
        self.ready.set()

    def stop(self) -> None:
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGINT)
            try:
                self.proc.wait(15)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(5)


def _naive(root: str, vehicles: int) -> bool:
    """A liveliness query right after open, as the issue measured: did it see them all?"""
    import zenoh

    session = zenoh.open(zenoh.Config())
    try:
        seen = set()
        for reply in session.liveliness().get(f"{root}/*/@fleetlog/recorder", timeout=2.0):
            if reply.ok is not None:
                seen.add(str(reply.ok.key_expr))
        return len(seen) == vehicles
    finally:
        session.close()


def _run(args: list[str], env: dict[str, str], timeout: float = 120.0) -> tuple[int, str, str]:
    done = subprocess.run(
        _fleetlog(*args), env=env, capture_output=True, text=True, timeout=timeout, check=False
    )
    return done.returncode, done.stdout, done.stderr


def measure(vehicles: int, fleet_runs: int, fetch_runs: int, naive_runs: int) -> dict[str, object]:
    root = f"race{os.getpid()}"
    names = [f"v{i:02d}" for i in range(vehicles)]
    env = dict(os.environ, NO_COLOR="1", TZ="UTC")
    result: dict[str, object] = {"vehicles": vehicles, "root": root}
    with tempfile.TemporaryDirectory(prefix="fleet_race_") as tmp:
        base = Path(tmp)
        recorders = [Recorder(n, root, base / "vehicles" / n, env) for n in names]
        try:
            started = time.monotonic()
            for rec in recorders:
                if not rec.ready.wait(60) or rec.proc.poll() is not None:
                    raise SystemExit(f"recorder {rec.vehicle} did not start: {''.join(rec.lines)}")
            result["start_seconds"] = round(time.monotonic() - started, 2)
            result["naive"] = [sum(_naive(root, vehicles) for _ in range(naive_runs)), naive_runs]

            ok, failures = 0, []
            for _ in range(fleet_runs):
                code, out, err = _run(["fleet", "--root", root, "--json"], env)
                listed = {json.loads(line)["vehicle"] for line in out.splitlines() if line}
                if code == 0 and listed == set(names):
                    ok += 1
                else:
                    failures.append(err.strip()[-3000:])
            result["fleet"] = [ok, fleet_runs]
            result["fleet_failures"] = failures[:3]

            ok, failures = 0, []
            for i in range(fetch_runs):
                out_dir = base / "shore" / str(i)
                code, _, err = _run(
                    ["fetch", "--all", "--latest", "--root", root, "-o", str(out_dir)], env
                )
                got = {p.name for p in out_dir.iterdir()} if out_dir.is_dir() else set()
                if code == 0 and got == set(names):
                    ok += 1
                else:
                    failures.append(f"exit {code}, got {sorted(got)}: {err.strip()[-300:]}")
            result["fetch"] = [ok, fetch_runs]
            result["fetch_failures"] = failures[:3]

            gone = recorders[-1]
            gone.stop()
            expect = [a for n in names for a in ("--expect", n)]
            stopped_dir = str(base / "shore" / "stopped")
            args = ["fetch", "--all", "--latest", "--root", root, "--wait", "2", *expect]
            code, _, err = _run([*args, "-o", stopped_dir], env)
            fetched = {p.name for p in (base / "shore" / "stopped").iterdir()}
            result["stopped"] = {
                "vehicle": gone.vehicle,
                "exit": code,
                "named": gone.vehicle in err.split("error:")[-1],
                "fetched_others": fetched == set(names[:-1]),
                "stderr": err.strip()[-400:],
            }
        finally:
            for rec in recorders:
                rec.stop()
    return result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--vehicles", type=int, default=3)
    parser.add_argument("--fleet-runs", type=int, default=5)
    parser.add_argument("--fetch-runs", type=int, default=3)
    parser.add_argument("--naive-runs", type=int, default=10)
    parser.add_argument("--in-netns", action="store_true", help="already in a namespace")
    opts = parser.parse_args()
    if not opts.in_netns:
        sys.path.insert(0, str(HERE))
        from netns import netns_argv, netns_unavailable

        why = netns_unavailable()
        if why is not None:
            raise SystemExit(f"no network namespace: {why}")
        argv = [sys.executable, __file__, *sys.argv[1:], "--in-netns"]
        raise SystemExit(subprocess.call(netns_argv(argv)))
    counts = (opts.vehicles, opts.fleet_runs, opts.fetch_runs, opts.naive_runs)
    print(json.dumps(measure(*counts)))


if __name__ == "__main__":
    main()
