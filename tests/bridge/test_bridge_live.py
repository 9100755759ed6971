"""``fleetlog bridge`` between a real MOOSDB (MOOS_BIN) and real Zenoh sessions.

Every test runs the CLI as a subprocess; the test holds a Zenoh router on loopback (every
process connects to it, as on a vehicle) and watches the MOOS side with real ``umm``
clients. Round trips: umm → bridge → recorder → alog; poke / the Python API → bridge →
MOOSDB → umm, and nothing comes back around; two communities on one Zenoh network; MOOS's
type rule; the MOOSDB and the router going away and coming back.
"""

from __future__ import annotations

import json
import re
import signal
import subprocess
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest
import zenoh
from alog_oracle import iter_entries
from helpers import Proc, run_cli
from moos_support import MoosDB, Umm, needs_moos, wait_until

from fleetlog.moos.alog import BinaryRef, parse_banner
from fleetlog.transport.session import SessionOptions
from fleetlog.wire.message import attachment_fields

pytestmark = needs_moos


def _config(mode: str, listen: str | None = None, connect: str | None = None) -> zenoh.Config:
    conf = zenoh.Config()
    conf.insert_json5("mode", json.dumps(mode))
    if listen:
        conf.insert_json5("listen/endpoints", json.dumps([listen]))
    if connect:
        conf.insert_json5("connect/endpoints", json.dumps([connect]))
    conf.insert_json5("scouting/multicast/enabled", "false")
    return conf


class Router:
    """A Zenoh router on loopback (a real one: Zenoh's own routing, in this process)."""

    def __init__(self, endpoint: str) -> None:
        self.endpoint = endpoint
        self.session: zenoh.Session | None = None
        self.start()

    def start(self) -> None:
        self.session = zenoh.open(_config("router", listen=self.endpoint))

    def stop(self) -> None:
        if self.session is not None:
            self.session.close()
            self.session = None


class Watch:
    """A Zenoh client of the router collecting every sample under a key expression."""

    def __init__(self, endpoint: str, key_expr: str) -> None:
        self.samples: list[tuple[str, bytes, tuple[float, str, str, str, float | None]]] = []
        self._lock = threading.Lock()
        self.session = zenoh.open(_config("client", connect=endpoint))
        self.sub = self.session.declare_subscriber(key_expr, self._on)

    def _on(self, sample: zenoh.Sample) -> None:
        attachment = sample.attachment
        meta = attachment_fields(attachment.to_bytes()) if attachment else (0.0, "", "", "", None)
        with self._lock:
            self.samples.append((str(sample.key_expr), sample.payload.to_bytes(), meta))

    def of(self, key: str) -> list[tuple[str, bytes, tuple[float, str, str, str, float | None]]]:
        with self._lock:
            return [s for s in self.samples if s[0] == key]

    def close(self) -> None:
        self.sub.undeclare()
        self.session.close()


@pytest.fixture
def router(endpoint: str) -> Iterator[Router]:
    r = Router(endpoint)
    yield r
    r.stop()


@pytest.fixture
def watches(router: Router) -> Iterator[Callable[[str], Watch]]:
    made: list[Watch] = []

    def make(key_expr: str) -> Watch:
        w = Watch(router.endpoint, key_expr)
        made.append(w)
        return w

    yield make
    for w in made:
        w.close()


def zargs(router: Router, mode: str = "peer") -> list[str]:
    return ["-m", mode, "-e", router.endpoint, "--no-multicast-scouting"]


def start_bridge(
    procs: Callable[..., Proc], db: MoosDB, router: Router, *extra: str, mode: str = "peer"
) -> Proc:
    proc = procs(
        "bridge", "--host", "127.0.0.1", "--port", str(db.port), *zargs(router, mode), *extra
    )
    proc.wait_for("connected to the MOOSDB")
    return proc


def poke(router: Router, vehicle: str, *assignments: str, env: dict[str, str]) -> None:
    """``fleetlog poke`` through the router. No recorder runs here, so none confirms the
    put, which poke reports as an error behind a router; each test checks the delivery
    itself, on the MOOS side."""
    result = run_cli("poke", "-v", vehicle, *zargs(router), *assignments, env=env)
    published = result.stderr.count(f"-> vehicle {vehicle}")
    assert published == len(assignments), result.stderr
    if result.returncode != 0:
        assert f"no recorder of vehicle {vehicle!r} confirmed the put" in result.stderr


def alog_of(root: Path) -> Path:
    (found,) = root.glob("MOOSLog_*/*.alog")
    return found


def test_umm_to_bridge_to_recorder_to_alog(
    moosdbs: Callable[..., MoosDB],
    umms: Callable[..., Umm],
    procs: Callable[..., Proc],
    router: Router,
    tmp_path: Path,
) -> None:
    db = moosdbs("alpha")
    logs = tmp_path / "logs"
    logs.mkdir()
    rec = procs("record", "--vehicle", "alpha", "--no-serve", *zargs(router), cwd=logs)
    rec.wait_for("recording vehicle")
    bridge = start_bridge(procs, db, router)
    watch = umms(db, "watch", "-s=UMM_X,UMM_B")
    wait_until(watch.connected, what="umm watch to connect")
    pub = umms(db, "pub", "-p=UMM_X@40,UMM_B:32@8", "--num_tx=60")
    assert pub.wait(30) == 0
    wait_until(lambda: len(watch.received()) >= 60, what="umm watch to receive 60 posts")
    time.sleep(1.0)
    assert bridge.stop() == 0
    assert rec.stop() == 0

    seen = watch.received()
    alog = alog_of(logs)
    lines = alog.read_text().splitlines(keepends=True)
    logstart = parse_banner([line.rstrip("\n") for line in lines[:12]]).logstart
    entries = list(iter_entries(lines))
    xs = [e for e in entries if e.key == "UMM_X"]
    bs = [e for e in entries if e.key == "UMM_B"]
    moos_xs = [r for r in seen if r[0] == "UMM_X"]
    # every value the MOOS side saw, once, in order, with its source and MOOS time
    assert [e.value for e in xs] == [float(r[3]) for r in moos_xs]
    assert len(bs) == len([r for r in seen if r[0] == "UMM_B"])
    for entry, row in zip(xs, moos_xs, strict=True):
        assert entry.source == "pub"
        assert abs(logstart + entry.offset - row[2]) < 0.002
    # the binary values went to the .blog, 32 bytes each
    assert bs
    assert all(isinstance(e.value, BinaryRef) and e.value.size == 32 for e in bs)
    # the MOOSDB's own variables name the vehicle for the MOOS-IvP tools
    db_time = [e for e in entries if e.key == "DB_TIME"]
    assert db_time
    assert {e.source for e in db_time} == {"MOOSDB_alpha"}


def test_poke_reaches_umm_and_nothing_comes_back(
    moosdbs: Callable[..., MoosDB],
    umms: Callable[..., Umm],
    procs: Callable[..., Proc],
    router: Router,
    watches: Callable[[str], Watch],
    cli_env: dict[str, str],
) -> None:
    db = moosdbs("alpha")
    bridge = start_bridge(procs, db, router)
    zwatch = watches("fleet/alpha/var/P_$*")
    watch = umms(db, "watch", "-s=P_D,P_S")
    wait_until(watch.connected, what="umm to connect")
    poke(router, "alpha", "P_D=1.5", "P_S:=hello world", env=cli_env)
    wait_until(lambda: len(watch.received()) >= 2, what="umm to receive the pokes")
    got = {r[0]: r for r in watch.received()}
    assert got["P_D"][1] == "uPokeDB"
    assert float(got["P_D"][3]) == 1.5
    assert got["P_S"][1] == "uPokeDB"
    assert got["P_S"][3].startswith("hello world")
    time.sleep(1.5)
    # one sample each on Zenoh: the poke's own; the bridge sent nothing back
    assert len(zwatch.of("fleet/alpha/var/P_D")) == 1
    assert len(zwatch.of("fleet/alpha/var/P_S")) == 1
    assert bridge.stop() == 0
    line = bridge.wait_for("stopped:")
    assert "Zenoh -> MOOS 2 of 2" in line


def test_published_in_order_arrive_in_order(
    moosdbs: Callable[..., MoosDB],
    umms: Callable[..., Umm],
    procs: Callable[..., Proc],
    router: Router,
    watches: Callable[[str], Watch],
) -> None:
    from fleetlog.api import Vehicle

    db = moosdbs("alpha")
    bridge = start_bridge(procs, db, router)
    zwatch = watches("fleet/alpha/var/NAV_X")
    watch = umms(db, "watch", "-s=NAV_X")
    wait_until(watch.connected, what="umm to connect")
    count = 2000
    opts = SessionOptions(mode="client", connect=(router.endpoint,), multicast_scouting=False)
    with Vehicle("alpha", source="uPlayBack", options=opts) as v:
        assert v.wait_for_subscriber("NAV_X", 5.0)
        t0 = time.time()
        for i in range(count):
            v.publish("NAV_X", float(i), time=t0 + i * 0.001)
        wait_until(lambda: len(watch.received()) >= count, timeout=20, what="every value")
    rows = watch.received()
    assert [float(r[3]) for r in rows] == [float(i) for i in range(count)]
    assert {r[1] for r in rows} == {"uPlayBack"}
    assert [round(r[2] - t0, 3) for r in rows[:3]] == [0.0, 0.001, 0.002]
    time.sleep(1.0)
    assert len(zwatch.of("fleet/alpha/var/NAV_X")) == count  # none came back
    bridge.stop()


def test_moos_type_rule(
    moosdbs: Callable[..., MoosDB],
    umms: Callable[..., Umm],
    procs: Callable[..., Proc],
    router: Router,
    cli_env: dict[str, str],
) -> None:
    db = moosdbs("alpha")
    bridge = start_bridge(procs, db, router)
    watch = umms(db, "watch", "-s=TC")
    pub = umms(db, "pub", "-p=TC@20", "--num_tx=3")
    assert pub.wait(20) == 0
    wait_until(lambda: len(watch.received()) >= 3, what="the double posts")
    poke(router, "alpha", "TC:=text", env=cli_env)
    poke(router, "alpha", "TC:=more text", env=cli_env)
    line = bridge.wait_for("TC is a double in the MOOSDB")
    assert "a string from uPokeDB was not posted" in line
    poke(router, "alpha", "TC=7", env=cli_env)
    wait_until(lambda: len(watch.received()) >= 4, what="the double poke")
    assert [float(r[3]) for r in watch.received()][-1] == 7.0
    assert bridge.stop() == 0
    assert "type clashes 2" in bridge.wait_for("stopped:")
    assert bridge.stderr.count("TC is a double") == 1  # said once


def test_two_bridged_communities_on_one_zenoh_network(
    moosdbs: Callable[..., MoosDB],
    umms: Callable[..., Umm],
    procs: Callable[..., Proc],
    router: Router,
    watches: Callable[[str], Watch],
    cli_env: dict[str, str],
) -> None:
    alpha = moosdbs("alpha")
    bravo = moosdbs("bravo")
    b_alpha = start_bridge(procs, alpha, router)
    b_bravo = start_bridge(procs, bravo, router)
    zwatch = watches("fleet/*/var/*")
    w_alpha = umms(alpha, "w_alpha", "-s=A_X,B_X,Q")
    w_bravo = umms(bravo, "w_bravo", "-s=A_X,B_X,Q")
    for w in (w_alpha, w_bravo):
        wait_until(w.connected, what="umm to connect")
    p_alpha = umms(alpha, "p_alpha", "-p=A_X@20", "--num_tx=10")
    p_bravo = umms(bravo, "p_bravo", "-p=B_X@20", "--num_tx=10")
    assert p_alpha.wait(20) == 0
    assert p_bravo.wait(20) == 0
    poke(router, "bravo", "Q=42", env=cli_env)
    wait_until(lambda: any(r[0] == "Q" for r in w_bravo.received()), what="Q in bravo")
    time.sleep(1.5)
    assert {r[0] for r in w_alpha.received()} == {"A_X"}
    assert {r[0] for r in w_bravo.received()} == {"B_X", "Q"}
    assert len(zwatch.of("fleet/alpha/var/A_X")) == 10
    assert len(zwatch.of("fleet/bravo/var/B_X")) == 10
    assert zwatch.of("fleet/alpha/var/B_X") == []
    assert zwatch.of("fleet/bravo/var/A_X") == []
    assert len(zwatch.of("fleet/bravo/var/Q")) == 1  # the poke only
    assert zwatch.of("fleet/alpha/var/Q") == []
    for b in (b_alpha, b_bravo):
        assert b.stop() == 0


def test_the_moosdb_not_up_restarting_and_back(
    moosdbs: Callable[..., MoosDB],
    umms: Callable[..., Umm],
    procs: Callable[..., Proc],
    router: Router,
    watches: Callable[[str], Watch],
    cli_env: dict[str, str],
) -> None:
    db = moosdbs("alpha", start=False)
    debug = watches("fleet/alpha/var/MOOS_DEBUG")
    bridge = procs(
        "bridge", "--host", "127.0.0.1", "--port", str(db.port), "-v", "alpha", *zargs(router)
    )
    bridge.wait_for("waiting for the MOOSDB")

    def said(text: str) -> bool:
        return any(text.encode() in s[1] for s in debug.of("fleet/alpha/var/MOOS_DEBUG"))

    # the vehicle is known: the fleet hears it on MOOS_DEBUG, from the bridge
    wait_until(lambda: said("waiting for the MOOSDB"), what="MOOS_DEBUG on Zenoh")
    db.start()
    bridge.wait_for("connected to the MOOSDB")
    zwatch = watches("fleet/alpha/var/AFTER")
    db.stop()
    bridge.wait_for("lost the MOOSDB")
    wait_until(lambda: said("lost the MOOSDB"), what="the loss on Zenoh")
    poke(router, "alpha", "DURING=1", env=cli_env)  # nowhere to post it: counted
    db.start()
    line = bridge.wait_for("reconnected to the MOOSDB")
    assert "1 samples from Zenoh could not be posted meanwhile" in line
    pub = umms(db, "pub", "-p=AFTER@20", "--num_tx=5")
    assert pub.wait(20) == 0
    wait_until(lambda: len(zwatch.of("fleet/alpha/var/AFTER")) == 5, what="posts after")
    assert bridge.stop() == 0
    assert "not forwarded 1," in bridge.wait_for("stopped:")


def test_the_zenoh_router_lost_and_back(
    moosdbs: Callable[..., MoosDB],
    umms: Callable[..., Umm],
    procs: Callable[..., Proc],
    router: Router,
) -> None:
    db = moosdbs("alpha")
    bridge = start_bridge(procs, db, router, mode="client")
    pub = umms(db, "pub", "-p=TICK@50")
    wait_until(pub.connected, what="umm to connect")
    time.sleep(0.5)
    router.stop()
    bridge.wait_for("lost every Zenoh link")
    time.sleep(1.0)
    router.start()
    line = bridge.wait_for("Zenoh link back", timeout=20)
    lost = int(re.search(r"; (\d+) messages from the MOOSDB could not", line).group(1))  # type: ignore[union-attr]
    assert lost > 10  # a second of TICK at 50 Hz, and the DB's own variables
    watch = Watch(router.endpoint, "fleet/alpha/var/TICK")
    try:
        wait_until(lambda: len(watch.of("fleet/alpha/var/TICK")) >= 5, what="TICK again")
    finally:
        watch.close()
    pub.stop()
    assert bridge.stop() == 0


def test_a_second_bridge_of_the_same_name_is_refused(
    moosdbs: Callable[..., MoosDB], procs: Callable[..., Proc], router: Router
) -> None:
    db = moosdbs("alpha")
    first = start_bridge(procs, db, router)
    second = procs("bridge", "--host", "127.0.0.1", "--port", str(db.port), *zargs(router))
    assert second.wait(20) == 1
    assert 'A client of this name ("fleetlog_bridge") already exists' in second.stderr
    assert "is another bridge running?" in second.stderr
    assert "Traceback" not in second.stderr
    assert first.stop() == 0


def test_values_keep_every_bit_into_the_alog(
    moosdbs: Callable[..., MoosDB],
    procs: Callable[..., Proc],
    router: Router,
    tmp_path: Path,
) -> None:
    """-nan keeps its sign, a string its bytes, a message its source, aux and MOOS time."""
    import asyncio

    from fleetlog.moos.requests import notify
    from fleetlog.transport.moos_client import MoosClient

    db = moosdbs("alpha")
    logs = tmp_path / "logs"
    logs.mkdir()
    rec = procs("record", "--vehicle", "alpha", "--no-serve", *zargs(router), cwd=logs)
    rec.wait_for("recording vehicle")
    bridge = start_bridge(procs, db, router)
    when = time.time()
    sent = [
        notify("F_NAN", float("-nan"), when, "pSensor", "filter", "alpha"),
        notify("F_POS", float("nan"), when + 0.01, "pSensor"),
        notify("F_TXT", "d\u00e9j\u00e0  vu, = x", when + 0.02, "pHelmIvP", "bhv_loiter"),
        notify("F_BIN", bytes(range(256)), when + 0.03, "iCamera"),
    ]

    async def post() -> None:
        client = MoosClient("poster", "127.0.0.1", db.port, on_mail=lambda m: None)
        await client.connect()
        client.send(sent)
        await asyncio.sleep(0.5)
        client.close()

    asyncio.run(post())
    time.sleep(1.0)
    assert bridge.stop() == 0
    assert rec.stop() == 0
    alog = alog_of(logs)
    lines = alog.read_text().splitlines(keepends=True)
    logstart = parse_banner([line.rstrip("\n") for line in lines[:12]]).logstart
    entries = {e.key: e for e in iter_entries(lines)}
    assert entries["F_NAN"].text.startswith("-nan")
    assert entries["F_POS"].text.startswith("nan")
    assert entries["F_TXT"].value == "d\u00e9j\u00e0  vu, = x"
    assert entries["F_TXT"].source == "pHelmIvP"
    assert entries["F_NAN"].source == "pSensor"
    blog = alog.with_suffix(".blog").read_bytes()
    assert bytes(range(256)) in blog
    for message in sent:
        assert abs(logstart + entries[message.key].offset - message.time) < 0.001


def test_a_real_plogger_logs_what_zenoh_posts(
    moosdbs: Callable[..., MoosDB],
    procs: Callable[..., Proc],
    router: Router,
    tmp_path: Path,
    cli_env: dict[str, str],
) -> None:
    """Zenoh -> bridge -> MOOSDB -> pLogger (essential-moos), when MOOS_BIN holds one."""
    from moos_support import moos_bin

    folder = moos_bin()
    assert folder is not None
    if not (folder / "pLogger").is_file():
        pytest.skip(f"MOOS_BIN={folder} holds no pLogger (essential-moos): test SKIPPED")
    db = moosdbs("alpha")
    bridge = start_bridge(procs, db, router)
    work = tmp_path / "plogger"
    work.mkdir()
    (work / "m.moos").write_text(
        f"ServerHost = 127.0.0.1\nServerPort = {db.port}\nCommunity = alpha\n\n"
        "ProcessConfig = pLogger\n{\n  WildCardLogging = true\n  AsyncLog = true\n"
        "  FileTimeStamp = false\n  File = REAL\n  Path = ./\n}\n"
    )
    with (work / "plogger.out").open("wb") as out:
        plogger = subprocess.Popen(
            [str(folder / "pLogger"), "m.moos", "--moos_suicide_disable"],
            cwd=work,
            stdin=subprocess.DEVNULL,
            stdout=out,
            stderr=subprocess.STDOUT,
        )
    try:
        wait_until(lambda: (work / "REAL" / "REAL.alog").exists(), what="pLogger's alog")
        time.sleep(1.5)  # its wildcard scan runs once a second
        poke(router, "alpha", "FROM_ZENOH=3.25", "FROM_ZENOH_S:=from shore", env=cli_env)
        time.sleep(3.0)
    finally:
        plogger.send_signal(signal.SIGINT)
        plogger.wait(10)
    text = (work / "REAL" / "REAL.alog").read_text(errors="replace")
    fields = [line.split() for line in text.splitlines() if line[:1].isdigit()]
    assert [(f[1], f[2], f[3]) for f in fields if f[1].startswith("FROM_ZENOH")] == [
        ("FROM_ZENOH", "uPokeDB", "3.25000"),
        ("FROM_ZENOH_S", "uPokeDB", "from"),
    ]
    assert bridge.stop() == 0


def test_replay_into_live_drives_the_moos_community(
    moosdbs: Callable[..., MoosDB],
    umms: Callable[..., Umm],
    procs: Callable[..., Proc],
    router: Router,
    tmp_path: Path,
) -> None:
    """replay --into-live -> bridge -> MOOSDB -> umm: every value, in order, under its
    original source; the live recorder logs each replayed value once (nothing comes back)."""
    from fleetlog.moos.alog import LineFormatter, format_banner

    db = moosdbs("alpha")
    logs = tmp_path / "logs"
    logs.mkdir()
    rec = procs("record", "--vehicle", "alpha", "--no-serve", *zargs(router), cwd=logs)
    rec.wait_for("recording vehicle")
    bridge = start_bridge(procs, db, router)
    watch = umms(db, "watch", "-s=NAV_X,DEPLOY")
    wait_until(watch.connected, what="umm to connect")

    fmt = LineFormatter()
    start = 1_700_000_000.0
    lines = [format_banner("./old/old.alog", start, "Tue Nov 14 22:13:20 2023")]
    for i in range(100):
        lines.append(fmt.double(0.5 + i * 0.01, "NAV_X", "pNav", float(i)))
    lines.append(fmt.string(1.6, "DEPLOY", "pHelmIvP", "true"))
    old = tmp_path / "old.alog"
    old.write_text("".join(lines))

    replay = procs("replay", str(old), "--as", "alpha", "--into-live", "--rate", "4",
                   *zargs(router))  # fmt: skip
    assert replay.wait(60) == 0, replay.stderr
    wait_until(lambda: len(watch.received()) >= 101, what="every replayed value in umm")
    rows = watch.received()
    assert [float(r[3]) for r in rows if r[0] == "NAV_X"] == [float(i) for i in range(100)]
    assert {r[1] for r in rows if r[0] == "NAV_X"} == {"pNav"}
    assert [(r[1], r[3].strip()) for r in rows if r[0] == "DEPLOY"] == [("pHelmIvP", "true")]
    time.sleep(1.0)
    assert bridge.stop() == 0
    assert rec.stop() == 0
    logged = [e for e in iter_entries(alog_of(logs).read_text().splitlines(keepends=True))]
    assert [e.value for e in logged if e.key == "NAV_X"] == [float(i) for i in range(100)]
    assert len([e for e in logged if e.key == "DEPLOY"]) == 1
