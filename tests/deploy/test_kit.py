"""fleetlog deploy: the fleet directory, its certificates, configurations, renew and revoke."""

from __future__ import annotations

import datetime as dt
import json
import stat
from pathlib import Path

import pytest
import zenoh
from deploy_support import make_fleet
from helpers import run_cli

from fleetlog.deploy import pki
from fleetlog.deploy.check import fleet_findings, machine_findings
from fleetlog.deploy.fleet import Fleet, Machine, parse_address
from fleetlog.deploy.kit import FleetKit, parse_holder
from fleetlog.errors import FormatError, UsageError
from fleetlog.transport.certs import check_tls_files, read_certificate, signed_by
from fleetlog.transport.session import SessionOptions
from fleetlog.wire.access import Role

NOW = dt.datetime(2026, 6, 1, tzinfo=dt.UTC)


def subjects(path: Path) -> list[str]:
    conf = zenoh.Config.from_file(str(path))
    acl = json.loads(conf.get_json("access_control"))
    return [cn for s in acl["subjects"] for cn in s["cert_common_names"]]


def test_init_writes_every_machine_and_keys_stay_private(tmp_path: Path) -> None:
    kit = make_fleet(tmp_path / "f")
    d = kit.directory
    for machine in ("shore", "vehicles/alpha", "vehicles/bravo", "operators/ops", "replays/sim"):
        assert (d / machine / "ca.pem").is_file()
        assert (d / machine / "zenoh.json5").is_file()
        assert (d / machine / "fleetlog.toml").is_file()
        for key in (d / machine).glob("*.key"):
            assert stat.S_IMODE(key.stat().st_mode) == 0o600, key
    assert stat.S_IMODE((d / "ca" / "ca.key").stat().st_mode) == 0o600
    assert not list((d / "vehicles").rglob("ca.key")), "the CA key went to a vehicle"
    ca = (d / "ca" / "ca.pem").read_bytes()
    for cert, cn in [
        ("vehicles/alpha/vehicle.pem", "fleetlog:vehicle:alpha"),
        ("vehicles/alpha/router.pem", "fleetlog:router:alpha"),
        ("shore/router.pem", "fleetlog:router:shore"),
        ("shore/operator.pem", "fleetlog:operator:shore"),
        ("operators/ops/operator.pem", "fleetlog:operator:ops"),
        ("replays/sim/replay.pem", "fleetlog:replay:sim"),
    ]:
        pem = (d / cert).read_bytes()
        assert read_certificate(pem).common_name == cn
        assert signed_by(pem, ca)
    router = read_certificate((d / "shore" / "router.pem").read_bytes())
    assert {"localhost", "127.0.0.1"} <= set(router.names)
    assert 'vehicle = "alpha"' in (d / "vehicles/alpha/fleetlog.toml").read_text()


@pytest.mark.parametrize(
    "name",
    [
        "shore/router.json5",
        "vehicles/alpha/router.json5",
        "shore/zenoh.json5",
        "vehicles/alpha/zenoh.json5",
        "operators/ops/zenoh.json5",
        "replays/sim/zenoh.json5",
    ],
)
def test_every_configuration_is_one_zenoh_accepts(tmp_path: Path, name: str) -> None:
    kit = make_fleet(tmp_path / "f")
    conf = zenoh.Config.from_file(str(kit.directory / name))
    assert json.loads(conf.get_json("scouting/multicast/enabled")) is False
    assert json.loads(conf.get_json("scouting/gossip/enabled")) is False
    assert json.loads(conf.get_json("transport/link/protocols")) == ["tls"]
    assert json.loads(conf.get_json("transport/link/tls/enable_mtls")) is True
    for key in ("listen/endpoints", "connect/endpoints"):
        value = json.loads(conf.get_json(key))
        items = value if isinstance(value, list) else [e for v in value.values() for e in v]
        assert all(e.startswith("tls/") for e in items), (key, items)
    if name.endswith("router.json5"):
        assert json.loads(conf.get_json("mode")) == "router"
        assert "fleetlog:vehicle:bravo" in subjects(kit.directory / name)


def test_every_router_runs_the_same_access_control(tmp_path: Path) -> None:
    kit = make_fleet(tmp_path / "f")
    acls = {
        json.dumps(json.loads(zenoh.Config.from_file(str(p)).get_json("access_control")))
        for p in kit.directory.rglob("router.json5")
    }
    assert len(acls) == 1


def test_revoke_removes_the_name_everywhere_and_says_what_to_redeploy(tmp_path: Path) -> None:
    kit = make_fleet(tmp_path / "f")
    old = (kit.directory / "vehicles/bravo/vehicle.pem").read_bytes()
    done = kit.revoke(Role.VEHICLE, "bravo", NOW, 365, "stolen")
    text = "\n".join(done.lines())
    assert "revoked fleetlog:vehicle:bravo" in text
    assert "fleetlog:vehicle:bravo:2" in text
    assert set(done.redeploy) == {"shore", "vehicles/alpha", "vehicles/bravo"}
    for router in kit.directory.rglob("router.json5"):
        names = subjects(router)
        assert "fleetlog:vehicle:bravo" not in names
        assert "fleetlog:vehicle:bravo:2" in names
    new = read_certificate((kit.directory / "vehicles/bravo/vehicle.pem").read_bytes())
    assert new.common_name == "fleetlog:vehicle:bravo:2"
    assert read_certificate(old).common_name == "fleetlog:vehicle:bravo"
    # a second revoke moves on again; the first name never comes back
    kit.revoke(Role.VEHICLE, "bravo", NOW, 365, "again")
    names = subjects(kit.directory / "shore/router.json5")
    assert "fleetlog:vehicle:bravo:3" in names
    assert not {"fleetlog:vehicle:bravo", "fleetlog:vehicle:bravo:2"} & set(names)
    assert [r.common_name for r in kit.load().revoked] == [
        "fleetlog:vehicle:bravo",
        "fleetlog:vehicle:bravo:2",
    ]


def test_renew_keeps_the_name_with_a_new_key_and_expiry(tmp_path: Path) -> None:
    kit = make_fleet(tmp_path / "f", days=20)
    path = kit.directory / "operators/ops/operator.pem"
    before = read_certificate(path.read_bytes())
    key_before = (kit.directory / "operators/ops/operator.key").read_bytes()
    done = kit.renew(Role.OPERATOR, "ops", dt.datetime.now(dt.UTC), 365)
    after = read_certificate(path.read_bytes())
    assert after.common_name == before.common_name
    assert after.not_after > before.not_after + dt.timedelta(days=300)
    assert (kit.directory / "operators/ops/operator.key").read_bytes() != key_before
    assert done.redeploy == {"operators/ops": ["operator.pem", "operator.key"]}


def test_check_warns_well_before_expiry(tmp_path: Path) -> None:
    kit = make_fleet(tmp_path / "f", days=20)
    now = dt.datetime.now(dt.UTC)
    findings = fleet_findings(kit, now)
    warnings = [f for f in findings if f.level == "warning"]
    assert len(warnings) == len(kit.load().holders())
    assert "fleetlog deploy renew" in warnings[0].text
    later = fleet_findings(kit, now + dt.timedelta(days=21))
    assert sum(f.level == "error" for f in later) == len(kit.load().holders())


def test_machine_check_names_identity_and_expiry(tmp_path: Path) -> None:
    kit = make_fleet(tmp_path / "f")
    config = kit.directory / "vehicles/alpha/zenoh.json5"
    findings = machine_findings(SessionOptions(config=config), dt.datetime.now(dt.UTC))
    text = "\n".join(map(str, findings))
    assert "identity fleetlog:vehicle:alpha: vehicle alpha" in text
    assert "valid until" in text
    assert not [f for f in findings if f.level != "ok"], text


def test_tls_problems_are_named(tmp_path: Path) -> None:
    kit = make_fleet(tmp_path / "f")
    ops = kit.directory / "operators/ops"
    files = {
        "root_ca_certificate": str(ops / "ca.pem"),
        "connect_certificate": str(ops / "operator.pem"),
        "connect_private_key": str(ops / "operator.key"),
    }
    assert "expired on" in check_tls_files(files, dt.datetime.now(dt.UTC) + dt.timedelta(days=400))
    assert "is valid only from" in check_tls_files(files, NOW - dt.timedelta(days=3650))
    missing = dict(files, connect_private_key=str(ops / "nope.key"))
    assert "cannot read" in check_tls_files(missing)
    assert "nope.key" in check_tls_files(missing)
    other = make_fleet(tmp_path / "g")
    foreign = dict(files, root_ca_certificate=str(other.directory / "ca" / "ca.pem"))
    assert "not signed by the CA" in check_tls_files(foreign)


def test_cli_init_check_revoke(tmp_path: Path, cli_env: dict[str, str]) -> None:
    d = tmp_path / "fleet"
    done = run_cli(
        "deploy", "init", str(d), "--vehicle", "alpha", "--vehicle", "bravo@10.0.0.7:7448",
        "--shore", "shore.example.org", "--shore", "203.0.113.5", "--operator", "ann",
        env=cli_env,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    fleet = FleetKit(d).load()
    assert fleet.etc == "/etc/fleetlog"
    conf = (d / "vehicles/alpha/router.json5").read_text()
    assert '"tls/shore.example.org:7447?prio=0-4#so_sndbuf=16384"' in conf
    assert '"tls/shore.example.org:7447?prio=5-7"' in conf
    assert "/etc/fleetlog/router.pem" in conf
    assert fleet.vehicles["bravo"].dial() == "tls/10.0.0.7:7448"
    shore = read_certificate((d / "shore/router.pem").read_bytes())
    assert {"shore.example.org", "203.0.113.5"} <= set(shore.names)
    again = run_cli("deploy", "init", str(d), "--vehicle", "x", "--shore", "h", env=cli_env)
    assert again.returncode == 1
    assert "already holds a fleet" in again.stderr
    check = run_cli("deploy", "check", str(d), env=cli_env)
    assert check.returncode == 0, check.stderr
    assert "fleetlog:operator:ann" in check.stdout
    revoke = run_cli("deploy", "revoke", str(d), "operator:ann", "--reason", "left", env=cli_env)
    assert revoke.returncode == 0, revoke.stderr
    assert "vehicles/alpha: router.json5" in revoke.stdout
    bad = run_cli("deploy", "revoke", str(d), "operator:nobody", env=cli_env)
    assert bad.returncode == 1
    assert "has no operator 'nobody'" in bad.stderr
    assert "Traceback" not in bad.stderr


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--vehicle", "al/pha", "--shore", "h"], "vehicle name 'al/pha'"),
        (["--vehicle", "shore", "--shore", "h"], "may not be named 'shore'"),
        (["--vehicle", "a@h:99999", "--shore", "h"], "port must be 1-65535"),
        (["--vehicle", "a", "--shore", "h", "--days", "0"], "--days must be 1 to 3650"),
        (["--vehicle", "a", "--shore", "h", "--replay-into", "zz"], "which the fleet does not"),
        (["--vehicle", "a", "--vehicle", "a", "--shore", "h"], "named twice"),
    ],
)
def test_cli_init_refuses_bad_input(
    tmp_path: Path, cli_env: dict[str, str], args: list[str], message: str
) -> None:
    done = run_cli("deploy", "init", str(tmp_path / "f"), *args, env=cli_env)
    assert done.returncode != 0
    assert message in done.stderr
    assert "Traceback" not in done.stderr


def test_parse_address_and_holder() -> None:
    assert parse_address("h", 7447) == ("h", 7447)
    assert parse_address("h:1", 7447) == ("h", 1)
    assert parse_address("[::1]:9", 7447) == ("::1", 9)
    assert parse_address("fe80::1", 7447) == ("fe80::1", 7447)
    for bad in ("", ":1", "[::1", "h:x", "a/b"):
        with pytest.raises(FormatError):
            parse_address(bad, 1)
    assert parse_holder("vehicle:alpha") == (Role.VEHICLE, "alpha")
    with pytest.raises(FormatError):
        parse_holder("boss:alpha")


def test_a_damaged_description_is_refused(tmp_path: Path) -> None:
    kit = make_fleet(tmp_path / "f")
    (kit.directory / "fleet.json").write_text('{"format": 9}')
    with pytest.raises(FormatError, match="not a fleet description"):
        kit.load()
    with pytest.raises(UsageError, match="holds no fleet"):
        FleetKit(tmp_path / "none").load()


def test_a_certificate_outlives_no_ca(tmp_path: Path) -> None:
    ca = pki.new_ca("short", NOW, days=10)
    leaf = pki.issue(ca, "fleetlog:vehicle:a", NOW, days=365)
    assert read_certificate(leaf.cert_pem).not_after <= read_certificate(ca.cert_pem).not_after


def test_fleet_round_trips() -> None:
    fleet = Fleet("x", "fleet", Machine("shore", ["h"]), {"a": Machine("a")}, ["o"]).check()
    assert Fleet.from_json(fleet.to_json()) == fleet
