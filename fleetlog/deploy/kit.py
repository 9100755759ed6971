"""A fleet directory: the CA, each machine's certificates and configurations, made and kept.

::

    FLEET/fleet.json                 the fleet's description (fleetlog.deploy.fleet)
    FLEET/ca/ca.pem, ca.key          the CA: keep ca.key off the vehicles, offline if you can
    FLEET/shore/                     /etc/fleetlog of the shore machine (router + shore tools)
    FLEET/vehicles/NAME/             /etc/fleetlog of vehicle NAME (router + its processes)
    FLEET/operators/NAME/            /etc/fleetlog (or ~/.config) of an operator's computer
    FLEET/replays/NAME/              /etc/fleetlog of a replay host

Each machine directory holds ``ca.pem``, its certificates and keys, ``zenoh.json5`` (what its
fleetlog commands use without ``-c``), ``fleetlog.toml`` and, on router machines,
``router.json5``.
"""

from __future__ import annotations

import datetime as dt
from dataclasses import dataclass
from pathlib import Path

from fleetlog.deploy import pki
from fleetlog.deploy.configs import (
    CA_FILE,
    ROUTER_CERT,
    ROUTER_KEY,
    client_config,
    router_config,
    settings_toml,
)
from fleetlog.deploy.fleet import SHORE, Fleet, Revoked
from fleetlog.errors import FormatError, UsageError
from fleetlog.storage.files import read_small, write_atomic
from fleetlog.wire.access import Role
from fleetlog.wire.access_profile import Identity

__all__ = ["CERT_FILES", "FleetKit", "Renewal"]

FLEET_FILE = "fleet.json"
#: a holder's certificate and key file names in its machine directory
CERT_FILES: dict[Role, tuple[str, str]] = {
    Role.ROUTER: (ROUTER_CERT, ROUTER_KEY),
    Role.VEHICLE: ("vehicle.pem", "vehicle.key"),
    Role.OPERATOR: ("operator.pem", "operator.key"),
    Role.REPLAY: ("replay.pem", "replay.key"),
}


@dataclass(frozen=True)
class Renewal:
    """What a renew or revoke changed: the files to copy, to which machines."""

    summary: str
    redeploy: dict[str, list[str]]

    def lines(self) -> list[str]:
        """The instructions, one line per machine."""
        out = [self.summary]
        for machine, files in self.redeploy.items():
            out.append(f"  {machine}: {', '.join(files)}")
        return out


class FleetKit:
    """A fleet directory on the operator's computer.

    Args:
        directory: the fleet directory.
    """

    def __init__(self, directory: Path) -> None:
        self.directory = directory.resolve()

    # -- reading

    def load(self) -> Fleet:
        """Read the fleet's description.

        Raises:
            UsageError: the directory holds no fleet.
            FormatError: the description is damaged.
        """
        path = self.directory / FLEET_FILE
        if not path.is_file():
            msg = f"{self.directory} holds no fleet (no {FLEET_FILE}); create one with deploy init"
            raise UsageError(msg)
        return Fleet.from_json(read_small(path, "fleet description"), str(path))

    def _ca(self) -> pki.KeyPair:
        ca = self.directory / "ca"
        return pki.KeyPair(
            read_small(ca / CA_FILE, "CA certificate"), read_small(ca / "ca.key", "CA key")
        )

    # -- making

    def init(self, fleet: Fleet, now: dt.datetime, days: int) -> list[str]:
        """Create the CA, every certificate and every configuration of a new fleet.

        Returns:
            The machine directories written.

        Raises:
            UsageError: the directory already holds a fleet.
            FormatError: a bad name or address.
        """
        fleet.check()
        if (self.directory / FLEET_FILE).exists():
            msg = f"{self.directory} already holds a fleet; renew or revoke instead of init"
            raise UsageError(msg)
        ca = pki.new_ca(fleet.name, now)
        write_atomic(self.directory / "ca" / CA_FILE, ca.cert_pem)
        write_atomic(self.directory / "ca" / "ca.key", ca.key_pem, 0o600)
        for where, who in fleet.holders():
            self._issue(fleet, ca, where, who, now, days)
        self._write_configs(fleet, ca.cert_pem)
        write_atomic(self.directory / FLEET_FILE, fleet.to_json().encode())
        return sorted({where for where, _ in fleet.holders()})

    def _issue(
        self,
        fleet: Fleet,
        ca: pki.KeyPair,
        where: str,
        who: Identity,
        now: dt.datetime,
        days: int,
    ) -> list[str]:
        names: tuple[str, ...] = ()
        if who.role is Role.ROUTER:
            machine = fleet.shore if who.name == SHORE else fleet.vehicles[who.name]
            names = machine.cert_names()
        pair = pki.issue(ca, who.common_name, now, names=names, days=days)
        cert_file, key_file = CERT_FILES[who.role]
        write_atomic(self.directory / where / cert_file, pair.cert_pem)
        write_atomic(self.directory / where / key_file, pair.key_pem, 0o600)
        info = pki.read_certificate(pair.cert_pem)
        fleet.expiry[f"{who.role.value}:{who.name}"] = info.not_after.isoformat()
        return [cert_file, key_file]

    def _write_configs(self, fleet: Fleet, ca_pem: bytes) -> None:
        base = str(self.directory)
        for machine in fleet.routers():
            where = SHORE if machine.name == SHORE else f"vehicles/{machine.name}"
            write_atomic(
                self.directory / where / "router.json5",
                router_config(fleet, machine, base).encode(),
            )
        machines: dict[str, Identity] = {}
        for where, who in fleet.holders():
            if who.role is not Role.ROUTER:
                machines[where] = who
        for where, who in machines.items():
            cert_file, key_file = CERT_FILES[who.role]
            write_atomic(self.directory / where / CA_FILE, ca_pem)
            write_atomic(
                self.directory / where / "zenoh.json5",
                client_config(fleet, where, cert_file, key_file, base).encode(),
            )
            vehicle = who.name if who.role is Role.VEHICLE else None
            write_atomic(
                self.directory / where / "fleetlog.toml", settings_toml(fleet, vehicle).encode()
            )

    def _router_files(self, fleet: Fleet) -> dict[str, list[str]]:
        out: dict[str, list[str]] = {}
        for machine in fleet.routers():
            where = SHORE if machine.name == SHORE else f"vehicles/{machine.name}"
            out[where] = ["router.json5"]
        return out

    def renew(self, role: Role, name: str, now: dt.datetime, days: int) -> Renewal:
        """Issue a fresh certificate (same identity, new key, new expiry) for one holder.

        Raises:
            UsageError: no fleet here.
            FormatError: no such holder.
        """
        fleet = self.load()
        where, who = fleet.find(role, name)
        files = self._issue(fleet, self._ca(), where, who, now, days)
        write_atomic(self.directory / FLEET_FILE, fleet.to_json().encode())
        expires = fleet.expiry[f"{role.value}:{name}"][:10]
        return Renewal(
            f"renewed {who.common_name} until {expires}; copy to the machine and restart its"
            " fleetlog services:",
            {where: files},
        )

    def revoke(self, role: Role, name: str, now: dt.datetime, days: int, reason: str) -> Renewal:
        """Revoke a holder's certificate and issue it a new identity.

        Zenoh has no revocation list: the old certificate stays valid until it expires, so
        its common name is removed from the access control of every router and never granted
        again; the holder gets the next generation of its name (``fleetlog:vehicle:bravo:2``).

        Raises:
            UsageError: no fleet here, or revoking the shore's router (make a new fleet).
            FormatError: no such holder.
        """
        fleet = self.load()
        where, who = fleet.find(role, name)
        fleet.revoked.append(Revoked(who.common_name, now.isoformat(), reason))
        key = f"{role.value}:{name}"
        fleet.generations[key] = who.generation + 1
        ca = self._ca()
        files = self._issue(fleet, ca, where, fleet.identity(role, name), now, days)
        self._write_configs(fleet, ca.cert_pem)
        write_atomic(self.directory / FLEET_FILE, fleet.to_json().encode())
        redeploy = self._router_files(fleet)
        redeploy.setdefault(where, []).extend(files)
        new = fleet.identity(role, name).common_name
        return Renewal(
            f"revoked {who.common_name}: no router grants it anything once it runs the new"
            f" router.json5 (until then it still does); {name}'s new identity is {new}."
            " Copy, then restart fleetlog-router (and the holder's services):",
            redeploy,
        )


def parse_holder(text: str) -> tuple[Role, str]:
    """Read ``ROLE NAME`` or ``ROLE:NAME`` (``vehicle:alpha``, ``router:shore``).

    Raises:
        FormatError: an unknown role or an empty name.
    """
    role_text, _, name = text.replace(" ", ":").partition(":")
    try:
        role = Role(role_text)
    except ValueError:
        roles = ", ".join(r.value for r in Role)
        msg = f"{text!r}: expected ROLE:NAME with ROLE one of {roles}"
        raise FormatError(msg) from None
    if not name:
        msg = f"{text!r}: expected ROLE:NAME (vehicle:alpha, router:shore, operator:ops)"
        raise FormatError(msg)
    return role, name
