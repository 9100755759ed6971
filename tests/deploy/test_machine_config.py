"""Machine-wide configuration: -c FILE > ZENOH_CONFIG > /etc/fleetlog/zenoh.json5, settings."""

from __future__ import annotations

from pathlib import Path

import pytest
from helpers import free_port, run_cli

from fleetlog.cli.settings import load_settings
from fleetlog.errors import TransportError, UsageError
from fleetlog.transport.session import SessionOptions, resolve_config


def peer_config(path: Path, port: int) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(
        f'{{mode: "peer", listen: {{endpoints: ["tcp/127.0.0.1:{port}"]}},'
        " scouting: {multicast: {enabled: false}}}"
    )
    return path


def test_precedence(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    etc = tmp_path / "etc"
    machine = peer_config(etc / "zenoh.json5", free_port())
    named = peer_config(tmp_path / "named.json5", free_port())
    given = peer_config(tmp_path / "given.json5", free_port())
    monkeypatch.setenv("FLEETLOG_ETC", str(etc))
    monkeypatch.delenv("ZENOH_CONFIG", raising=False)
    assert resolve_config(None).path == machine
    assert resolve_config(None).how == "machine-wide"
    monkeypatch.setenv("ZENOH_CONFIG", str(named))
    assert resolve_config(None).path == named
    assert resolve_config(given).path == given
    assert resolve_config(given).how == "--config"
    monkeypatch.setenv("ZENOH_CONFIG", str(tmp_path / "typo.json5"))
    with pytest.raises(TransportError, match=r"ZENOH_CONFIG names .*typo\.json5"):
        resolve_config(None)
    monkeypatch.delenv("ZENOH_CONFIG")
    monkeypatch.setenv("FLEETLOG_ETC", str(tmp_path / "nothing"))
    assert resolve_config(None).path is None
    assert SessionOptions(machine_config=False).source().path is None


def test_verbose_says_which_was_used(tmp_path: Path, cli_env: dict[str, str]) -> None:
    etc = tmp_path / "etc"
    peer_config(etc / "zenoh.json5", free_port())
    (etc / "fleetlog.toml").write_text('root = "harbour"\n')
    env = dict(cli_env, FLEETLOG_ETC=str(etc))
    done = run_cli("--verbose", "fleet", env=env)
    assert f"Zenoh configuration: {etc / 'zenoh.json5'} (this machine's configuration)" in (
        done.stderr
    )
    assert "settings: " in done.stderr
    assert "root='harbour'" in done.stderr
    named = peer_config(tmp_path / "named.json5", free_port())
    done = run_cli("--verbose", "fleet", env=dict(env, ZENOH_CONFIG=str(named)))
    assert f"{named} (named by ZENOH_CONFIG)" in done.stderr
    given = peer_config(tmp_path / "given.json5", free_port())
    done = run_cli("--verbose", "fleet", "-c", str(given), env=env)
    assert f"{given} (given by -c/--config)" in done.stderr


def test_settings_give_the_root_and_an_option_wins(tmp_path: Path, cli_env: dict[str, str]) -> None:
    settings = tmp_path / "s.toml"
    settings.write_text('root = "harbour/one"\n')
    port = free_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    from helpers import Proc

    rec = Proc(
        ["record", "--vehicle", "kayak", "--root", "harbour/one", "-l", endpoint,
         "--no-multicast-scouting"], tmp_path, cli_env,
    )  # fmt: skip
    try:
        rec.wait_for("recording vehicle")
        common = ["-e", endpoint, "--no-multicast-scouting"]
        found = run_cli("--settings", str(settings), "sessions", "kayak", *common, env=cli_env)
        assert found.returncode == 0, found.stderr
        other = run_cli(
            "--settings", str(settings), "sessions", "kayak", "--root", "fleet", *common,
            env=cli_env,
        )  # fmt: skip
        assert other.returncode == 1
    finally:
        rec.stop()
        rec.close()


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("root = ", "is not TOML"),
        ('colour = "red"', "unknown setting 'colour'"),
        ("root = 3", "root must be a non-empty string"),
        ('vehicle = ""', "vehicle must be a non-empty string"),
    ],
)
def test_bad_settings_are_refused(tmp_path: Path, text: str, message: str) -> None:
    path = tmp_path / "s.toml"
    path.write_text(text)
    with pytest.raises(UsageError, match=message):
        load_settings(path)


def test_missing_settings_file(tmp_path: Path, cli_env: dict[str, str]) -> None:
    done = run_cli("--settings", str(tmp_path / "no.toml"), "fleet", env=cli_env)
    assert done.returncode == 1
    assert "does not exist" in done.stderr
