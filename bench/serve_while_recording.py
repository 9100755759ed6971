"""The recorder's rate and loss while the same process serves a fetch (and a grep) at full rate.

One helper process runs what a vehicle runs: a :class:`RecorderService` (no mission:
wildcard logging into its working directory) and, in the same process, a :class:`LogServer`
over that directory that knows the recorder's open session. (The recorder does not host the
server yet; here the server has a Zenoh session of its own in the same process, so it competes
for the same GIL and the same two cores as it will.) A publisher process
(``benchlib.py publisher``: MoosPublisher, BLOCK) puts N doubles as fast as it can; meanwhile
this process fetches a generated 200 MB session from the vehicle again and again, and greps
it, as fast as the vehicle answers.

Each round runs the publisher with the server idle, then under each load (``--load``: a
fetch, a grep, or both), and reports the recorder's rate (N / time until the end marker is
in the alog) and whether every sample was logged (counts per key, and the recorder's own
``lost`` counter).

    python bench/serve_while_recording.py             # 200k samples, 3 rounds
    python bench/serve_while_recording.py -n 400000 --rounds 5
"""

from __future__ import annotations

import argparse
import json
import shutil
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

from benchlib import (
    END,
    VEHICLE,
    Helper,
    Tail,
    count_alog,
    free_port,
    key_names,
    loadavg,
    spread,
)
from fetch_throughput import SESSION, make_session

from fleetlog.errors import FleetlogError
from fleetlog.shore.client import FleetClient
from fleetlog.shore.fetch import fetch_session
from fleetlog.wire.query import GrepRequest

HERE = Path(__file__).resolve()


def role_vehicle(args: argparse.Namespace) -> None:
    """Run a recorder and a log server in this process until "exit" arrives on stdin."""
    from fleetlog.moos.mission import LoggerConfig
    from fleetlog.query.server import LogServer
    from fleetlog.recorder.service import RecorderService, ServiceOptions
    from fleetlog.storage.catalog import LogCatalog
    from fleetlog.transport.session import SessionOptions, open_session

    workdir = Path(args.workdir)
    service = RecorderService(
        LoggerConfig.default(),
        ServiceOptions(
            vehicle=VEHICLE,
            zenoh=SessionOptions(listen=(args.listen,), multicast_scouting=False),
            cwd=workdir,
        ),
    )
    thread = threading.Thread(target=service.run, daemon=True)
    thread.start()
    if not service.ready.wait(30) or service.recorder is None:
        raise RuntimeError("the recorder did not start")
    recorder = service.recorder

    def active() -> Path | None:
        session = recorder.session
        return None if session is None else session.dir_path

    assert recorder.session is not None
    alog = recorder.session.dir_path / f"{recorder.session.root}.alog"
    catalog = LogCatalog(workdir, vehicle=VEHICLE, active=active)
    zenoh_session = open_session(SessionOptions(listen=(args.serve,), multicast_scouting=False))
    with LogServer(zenoh_session, catalog, announce=True):
        print(json.dumps({"event": "ready", "alog": str(alog)}), flush=True)
        for line in sys.stdin:
            if line.strip() == "exit":
                break
    zenoh_session.close()
    service.stop()
    thread.join(30)
    print(json.dumps({"event": "stopped", "stats": recorder.stats.as_dict()}), flush=True)


class Load:
    """Fetches the big session (and greps it) from the vehicle in a loop, in threads."""

    def __init__(self, endpoint: str, out: Path, kinds: tuple[str, ...]) -> None:
        from fleetlog.transport.session import SessionOptions

        self.client = FleetClient.open(
            SessionOptions(connect=(endpoint,), multicast_scouting=False)
        )
        self.out = out
        self.stop = threading.Event()
        self.fetched = 0
        self.grepped = 0
        self.errors: list[str] = []
        work = {"fetch": self._fetch, "grep": self._grep}
        self.threads = [threading.Thread(target=work[kind], daemon=True) for kind in kinds]

    def __enter__(self) -> Load:
        for thread in self.threads:
            thread.start()
        return self

    def _fetch(self) -> None:
        while not self.stop.is_set():
            shutil.rmtree(self.out, ignore_errors=True)
            try:
                outcome = fetch_session(self.client, VEHICLE, SESSION, self.out)
            except FleetlogError as err:
                self.errors.append(str(err))
                return
            self.fetched += outcome.received

    def _grep(self) -> None:
        while not self.stop.is_set():
            try:
                stream = self.client.grep(VEHICLE, SESSION, GrepRequest(("VAR_1*",), limit=20000))
                self.grepped += sum(1 for _ in stream)
            except FleetlogError as err:
                self.errors.append(str(err))
                return

    def __exit__(self, *exc: object) -> None:
        self.stop.set()
        for thread in self.threads:
            thread.join(120)
        self.client.close()


class VehicleProcess(Helper):
    """This file's ``vehicle`` role in a subprocess (JSON events out, commands in)."""

    def __init__(self, args: list[str]) -> None:
        self.proc = subprocess.Popen(
            [sys.executable, str(HERE), "vehicle", *args],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
            bufsize=1,
        )


def run(
    n: int, keys: int, paths: tuple[Path, Path], endpoints: tuple[int, str], load: str
) -> dict[str, object]:
    """One publisher run against the vehicle, with the server idle or under ``load``."""
    work, alog = paths
    port, endpoint = endpoints
    tail = Tail(alog)
    tail.read_lines()  # skip what earlier runs logged
    args = ["--connect", f"tcp/127.0.0.1:{port}", "-n", str(n), "--keys", str(keys)]
    pub = Helper("publisher", args)
    kinds = () if load == "idle" else tuple(load.split("+"))
    loader = Load(endpoint, work / "shore", kinds) if kinds else None
    try:
        pub.read()
        if loader is not None:
            loader.__enter__()
            time.sleep(0.5)  # the load is at full speed before the burst starts
        pub.send("go")
        sent = pub.read()
        seen_end = None
        deadline = time.monotonic() + max(120.0, n / 2000)
        marker = END.encode()
        while seen_end is None and time.monotonic() < deadline:
            for line in tail.read_lines():
                if marker in line:
                    seen_end = time.time()
            if seen_end is None:
                time.sleep(0.005)
    finally:
        if loader is not None:
            loader.__exit__()
        pub.finish()
        tail.close()
    return {
        "rate": n / (seen_end - sent["t0"]) if seen_end else 0.0,
        "fetched": loader.fetched if loader else 0,
        "grepped": loader.grepped if loader else 0,
        "errors": loader.errors if loader else [],
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("-n", type=int, default=200_000, help="samples per run")
    parser.add_argument("--keys", type=int, default=4)
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--mb", type=int, default=200, help="size of the fetched session")
    parser.add_argument(
        "--load",
        action="append",
        choices=("fetch", "grep", "fetch+grep"),
        help="what the shore asks meanwhile (repeatable) [default: fetch and fetch+grep]",
    )
    args = parser.parse_args()
    loads = ["idle", *(args.load or ["fetch", "fetch+grep"])]
    rates: dict[str, list[float]] = {load: [] for load in loads}
    with tempfile.TemporaryDirectory(prefix="fleetlog-bench-") as tmp:
        work = Path(tmp)
        vehicle_dir = work / "vehicle"
        make_session(vehicle_dir, args.mb)
        port, serve_port = free_port(), free_port()
        endpoint = f"tcp/127.0.0.1:{serve_port}"
        listen = f"tcp/127.0.0.1:{port}"
        vehicle = VehicleProcess(
            ["--workdir", str(vehicle_dir), "--listen", listen, "--serve", endpoint]
        )
        ready = vehicle.read()
        alog = Path(str(ready["alog"]))
        print(f"{args.n:,} doubles per run, {args.mb} MB session served; load {loadavg()}")
        for round_ in range(args.rounds):
            figures = []
            for load in loads:
                result = run(args.n, args.keys, (work, alog), (port, endpoint), load)
                rates[load].append(float(str(result["rate"])))
                extra = ""
                if load != "idle":
                    extra = (
                        f" (fetched {int(str(result['fetched'])) / 1e6:,.0f} MB,"
                        f" grepped {result['grepped']:,} entries)"
                    )
                    if result["errors"]:
                        extra += f" errors: {result['errors'][:2]}"
                figures.append(f"{load} {result['rate']:,.0f}/s{extra}")
            print(f"round {round_ + 1}: " + "; ".join(figures) + f"; load {loadavg()}", flush=True)
        vehicle.send("exit")
        stopped = vehicle.read(timeout=120)
        vehicle.finish()
        counts, _ = count_alog(alog, key_names(args.keys))
    stats = stopped["stats"]
    runs = args.rounds * len(loads)
    expected = args.n * runs
    logged = sum(counts.values())
    # Every run puts n/keys values on each key: each key must hold exactly that many per run.
    per_key = all(count == runs * (args.n // args.keys) for count in counts.values())
    loss_free = logged == expected and per_key and stats.get("lost") == 0
    for load in loads:
        line = f"recorder while the server is {load + ':':<12} {spread(rates[load])} samples/s"
        if load != "idle":
            ratio = [b / a for a, b in zip(rates["idle"], rates[load], strict=True) if a]
            line += f"  ({spread(ratio, '{:.2f}')} of idle)"
        print(line)
    print(
        f"logged {logged:,} of {expected:,} samples, recorder lost {stats.get('lost')}:"
        f" {'loss-free' if loss_free else 'LOSS'}; load {loadavg()}"
    )


if __name__ == "__main__":
    if len(sys.argv) > 1 and sys.argv[1] == "vehicle":
        role = argparse.ArgumentParser()
        role.add_argument("--workdir", required=True)
        role.add_argument("--listen", required=True)
        role.add_argument("--serve", required=True)
        role_vehicle(role.parse_args(sys.argv[2:]))
    else:
        main()
