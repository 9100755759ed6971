"""The security profile on real routers: mutual TLS and access control, two vehicles.

Everything is real: certificates made by ``FleetKit`` (``fleetlog deploy init``), the shore's
and the vehicles' routers (``fleetlog router``), the vehicles' recorders (``fleetlog record``
reading their machine's /etc/fleetlog), the CLI as a subprocess. Each forbidden action is
tried by a peer without a certificate, with the other vehicle's, with one from another CA
bearing a valid name, and with a valid certificate in the wrong role; each is refused, and
the operator sees the refusal.
"""

from __future__ import annotations

import json
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
import zenoh
from deploy_support import OPS, REPLAY, SecureFleet, alog_text, make_fleet, vehicle_dir

from fleetlog.errors import TransportError
from fleetlog.transport.session import SessionOptions, open_session

ALPHA, BRAVO = vehicle_dir("alpha"), vehicle_dir("bravo")


def _start(
    tmp_path_factory: pytest.TempPathFactory, env: dict[str, str], config: pytest.Config
) -> SecureFleet:
    """Two vehicles, their routers and the shore's, all up and seen by the operator.

    Five processes on a shared CI machine: twice in 13 runs the fleet did not come up (a
    router's port taken in between, once; bravo never listed in 60 s, once). It is started
    once more, with new ports, and the first failure is written on the terminal with what
    every process said (past pytest's capture); a second failure fails every test of the
    module.
    """
    why = ""
    for attempt in (1, 2):
        fleet = SecureFleet(tmp_path_factory.mktemp("secure"), env, ("alpha", "bravo"))
        try:
            fleet.start_all()
            seen = fleet.wait_vehicles(OPS, {"alpha", "bravo"})
            if seen >= {"alpha", "bravo"}:
                return fleet
            why = f"the operator saw {sorted(seen)}:\n{fleet.diagnosis()}"
        except AssertionError as err:
            why = f"{err}\n{fleet.diagnosis()}"
        fleet.close()
        if attempt == 1:
            reporter = config.pluginmanager.get_plugin("terminalreporter")
            capture = config.pluginmanager.get_plugin("capturemanager")
            if reporter is not None and capture is not None:
                with capture.global_and_fixture_disabled():
                    reporter.write_line(f"\nWARNING: the secured fleet did not come up: {why}")
    pytest.fail(f"the secured fleet did not come up twice: {why}")


@pytest.fixture(scope="module")
def secure(
    tmp_path_factory: pytest.TempPathFactory, pytestconfig: pytest.Config
) -> Iterator[SecureFleet]:
    import os

    env = dict(os.environ)
    env.update(TZ="UTC", NO_COLOR="1")
    fleet = _start(tmp_path_factory, env, pytestconfig)
    try:
        yield fleet
    finally:
        fleet.close()


def publish(session: zenoh.Session, key: str, value: str) -> None:
    """Put once a subscriber is known, then wait for the router to pass it on."""
    pub = session.declare_publisher(key)
    deadline = time.monotonic() + 3
    while not pub.matching_status.matching and time.monotonic() < deadline:
        time.sleep(0.01)
    pub.put(value)
    time.sleep(0.3)
    pub.undeclare()


def logged(secure: SecureFleet, vehicle: str, needle: str, timeout: float = 5.0) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if needle in alog_text(secure.directory / "logs" / vehicle):
            return True
        time.sleep(0.2)
    return False


def replies(session: zenoh.Session, selector: str, timeout: float = 3.0) -> list[str]:
    out = []
    for reply in session.get(selector, timeout=timeout):
        if reply.ok is not None:
            out.append(reply.ok.payload.to_string())
        else:
            out.append("ERR " + reply.err.payload.to_string())
    return out


# -- what works ----------------------------------------------------------------------------


def test_record_fetch_and_grep_through_the_routers(secure: SecureFleet, tmp_path: Path) -> None:
    with secure.session(ALPHA) as app:
        publish(app, "fleet/alpha/var/DEPTH", "12.5")
    assert logged(secure, "alpha", "DEPTH")
    code, out, err = secure.cli(OPS, "sessions", "alpha")
    assert code == 0, err
    assert "MOOSLog_" in out
    code, _, err = secure.cli(OPS, "fetch", "alpha", "--latest", "-o", str(tmp_path))
    assert code == 0, err
    # the session is still being written: fetched as far as it goes, kept as .part
    (part,) = tmp_path.rglob("*.alog.part")
    assert b"DEPTH" in part.read_bytes()
    code, out, err = secure.cli(OPS, "query", "alpha", "DEPTH")
    assert code == 0, err
    assert "12.5" in out


def test_an_operator_sends_recorder_commands(secure: SecureFleet) -> None:
    # A valid command: poke exits non-zero when the recorder refuses one (and says why).
    code, out, err = secure.cli(
        OPS, "poke", "--vehicle", "alpha", "PLOGGER_CMD:=LOG_REQUEST=OPS_WAS_HERE"
    )
    assert code == 0, err
    assert "recorder of alpha: LOG_REQUEST=OPS_WAS_HERE" in out
    assert logged(secure, "alpha", "OPS_WAS_HERE")


def test_a_replay_host_replays_under_its_prefix(secure: SecureFleet) -> None:
    with secure.session(OPS) as ops:
        got: list[str] = []
        sub = ops.declare_subscriber(
            "fleet/sim_alpha/var/**", lambda s: got.append(str(s.key_expr))
        )
        try:
            code, _, err = secure.cli(
                REPLAY, "replay", "alpha:latest", "--prefix", "sim_", "--fast", "--no-keys",
                "--wait", "5", "--cache-dir", str(secure.directory / "cache"),
            )  # fmt: skip
            time.sleep(0.5)
        finally:
            sub.undeclare()
    assert code == 0, err
    assert any(k.startswith("fleet/sim_alpha/var/") for k in got)


# -- a peer without a certificate ----------------------------------------------------------


def test_no_certificate_cannot_open_and_says_why(secure: SecureFleet) -> None:
    bare = secure.tweaked_config(OPS, connect_certificate=None, connect_private_key=None)
    with pytest.raises(TransportError, match="shows no certificate"):
        open_session(SessionOptions(config=bare, machine_config=False))
    code, _, err = secure.cli(OPS, "fleet", "-c", str(bare))
    assert code == 1
    assert "shows no certificate" in err


def test_plain_tcp_is_not_accepted(secure: SecureFleet) -> None:
    port = secure.fleet.shore.port
    options = SessionOptions(
        mode="client", connect=(f"tcp/127.0.0.1:{port}",), multicast_scouting=False
    )
    with pytest.raises(TransportError):
        open_session(options)


# -- another vehicle's certificate -----------------------------------------------------------


def test_bravo_cannot_publish_alphas_variables(secure: SecureFleet) -> None:
    with secure.session(BRAVO) as bravo:
        bravo.put("fleet/alpha/var/FORGED", "bravo-was-here")
        bravo.put("fleet/alpha/var/PLOGGER_CMD", "bravo-command")
        time.sleep(0.5)
    with secure.session(ALPHA) as app:
        publish(app, "fleet/alpha/var/MARKER", "after-bravo")
    assert logged(secure, "alpha", "after-bravo")
    text = alog_text(secure.directory / "logs" / "alpha")
    assert "bravo-was-here" not in text
    assert "bravo-command" not in text


def test_bravo_cannot_answer_or_appear_as_alpha(secure: SecureFleet) -> None:
    def forge(query: zenoh.Query) -> None:
        query.reply("fleet/alpha/@fleetlog/latest", json.dumps({"vehicle": "forged"}))

    with secure.session(BRAVO) as bravo:
        q = bravo.declare_queryable("fleet/alpha/@fleetlog/latest", forge)
        token = bravo.liveliness().declare_token("fleet/alpha/@fleetlog/serve")
        time.sleep(0.5)
        try:
            with secure.session(OPS) as ops:
                answers = replies(ops, "fleet/alpha/@fleetlog/latest")
                tokens = [
                    str(r.ok.key_expr)
                    for service in ("recorder", "serve")
                    for r in ops.liveliness().get(f"fleet/*/@fleetlog/{service}", timeout=2)
                    if r.ok is not None
                ]
        finally:
            token.undeclare()
            q.undeclare()
    assert answers
    assert all('"forged"' not in a for a in answers)
    assert "fleet/alpha/@fleetlog/serve" not in tokens
    assert "fleet/alpha/@fleetlog/recorder" in tokens


def test_bravo_cannot_read_alpha(secure: SecureFleet) -> None:
    with secure.session(BRAVO) as bravo:
        assert replies(bravo, "fleet/alpha/@fleetlog/sessions") == []
        got: list[str] = []
        sub = bravo.declare_subscriber("fleet/alpha/var/**", lambda s: got.append("x"))
        time.sleep(0.3)
        with secure.session(ALPHA) as app:
            publish(app, "fleet/alpha/var/SECRET", "1")
        sub.undeclare()
    assert got == []
    # and the vehicle's own command line says the silence may be a refusal
    code, _, err = secure.cli(BRAVO, "sessions", "alpha")
    assert code == 1
    assert "access control may have refused the liveliness query" in err
    assert "fleet/alpha/@fleetlog/recorder" in err


# -- a certificate from another CA bearing a valid name ---------------------------------------


def test_another_ca_with_a_valid_name_is_refused(secure: SecureFleet, tmp_path: Path) -> None:
    other = make_fleet(tmp_path / "other")  # the same names, another CA
    stolen_name = other.directory / "operators" / "ops"
    # Trusting our CA (so the shore's certificate verifies), showing the other CA's
    # fleetlog:operator:ops: the shore's router refuses the handshake.
    mixed = secure.tweaked_config(
        OPS,
        connect_certificate=stolen_name / "operator.pem",
        connect_private_key=stolen_name / "operator.key",
    )
    with pytest.raises(TransportError, match="not signed by the CA"):
        open_session(SessionOptions(config=mixed, machine_config=False))
    # With its own CA's configuration, it cannot verify the shore either.
    own = secure.tweaked_config(
        OPS,
        root_ca_certificate=stolen_name / "ca.pem",
        connect_certificate=stolen_name / "operator.pem",
        connect_private_key=stolen_name / "operator.key",
    )
    with pytest.raises(TransportError, match="Unable to connect"):
        open_session(SessionOptions(config=own, machine_config=False))


# -- a valid certificate in the wrong role ----------------------------------------------------


def test_an_operator_cannot_publish_a_vehicles_variables(secure: SecureFleet) -> None:
    code, _, err = secure.cli(OPS, "poke", "--vehicle", "alpha", "NAV_X=99")
    assert code == 1
    assert "fleetlog:operator:ops may not publish NAV_X" in err
    with secure.session(OPS) as ops:
        ops.put("fleet/alpha/var/NAV_X", "operator-forged")
        time.sleep(0.3)
    with secure.session(ALPHA) as app:
        publish(app, "fleet/alpha/var/MARKER", "after-operator")
    assert logged(secure, "alpha", "after-operator")
    assert "operator-forged" not in alog_text(secure.directory / "logs" / "alpha")


def test_an_operator_cannot_serve_as_a_vehicle(secure: SecureFleet) -> None:
    with secure.session(OPS) as rogue:
        q = rogue.declare_queryable(
            "fleet/bravo/@fleetlog/status", lambda q: q.reply(q.key_expr, "rogue")
        )
        time.sleep(0.3)
        try:
            with secure.session(OPS) as ops:
                answers = replies(ops, "fleet/bravo/@fleetlog/status")
        finally:
            q.undeclare()
    assert answers
    assert "rogue" not in answers


def test_a_replay_host_cannot_command_or_feed_a_live_vehicle(secure: SecureFleet) -> None:
    with secure.session(REPLAY) as replay:
        assert replies(replay, "fleet/alpha/@fleetlog/control?cmd=status") == []
        replay.put("fleet/alpha/var/PLOGGER_CMD", "replay-command")
        replay.put("fleet/alpha/var/NAV_X", "replay-forged")
        time.sleep(0.3)
    with secure.session(ALPHA) as app:
        publish(app, "fleet/alpha/var/MARKER", "after-replay")
    assert logged(secure, "alpha", "after-replay")
    text = alog_text(secure.directory / "logs" / "alpha")
    assert "replay-command" not in text
    assert "replay-forged" not in text


def test_a_vehicle_cannot_list_the_fleet_and_is_told_why(secure: SecureFleet) -> None:
    code, _, err = secure.cli(ALPHA, "fleet")
    assert code == 1
    assert "access control may have refused the liveliness query" in err


def test_a_plain_zenoh_client_lists_and_fetches(secure: SecureFleet, tmp_path: Path) -> None:
    """Written from docs/wire.md and docs/deploy.md alone, with an operator's certificate."""
    import ast
    import subprocess
    import sys

    script = Path(__file__).with_name("plain_client.py")
    imported = {
        alias.name.split(".")[0]
        for node in ast.walk(ast.parse(script.read_text()))
        if isinstance(node, ast.Import | ast.ImportFrom)
        for alias in (
            node.names if isinstance(node, ast.Import) else [ast.alias(node.module or "")]
        )
    }
    assert "fleetlog" not in imported
    code, _, err = secure.cli(OPS, "poke", "--vehicle", "alpha", "LOGGER_RESTART=true")
    assert code == 0, err
    time.sleep(1.0)
    done = subprocess.run(
        [sys.executable, str(script), str(secure.config(OPS)), str(tmp_path)],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert done.returncode == 0, done.stderr
    lines = [json.loads(x) for x in done.stdout.splitlines()]
    assert set(lines[0]["vehicles"]) >= {"alpha", "bravo"}
    fetched = [x for x in lines[1:] if x["vehicle"] == "alpha"]
    assert any(x["file"].endswith(".alog") for x in fetched)
    for item in fetched:
        path = tmp_path / "alpha"
        (copy,) = path.glob(f"*/{item['file']}")
        assert copy.stat().st_size == item["size"]


def test_status_says_which_configuration_and_identity(secure: SecureFleet) -> None:
    code, _, err = secure.cli(OPS, "status", "alpha")
    assert code == 0, err
    assert f"{secure.config(OPS)} (this machine's configuration)" in err
    assert "identity fleetlog:operator:ops: operator ops" in err
    assert "valid until" in err
    assert '"wire": 2' in secure.cli(OPS, "status", "alpha", "--json")[1]
