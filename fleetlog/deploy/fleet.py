"""A fleet's description (``fleet.json``): its machines, identities and what is revoked.

``fleetlog deploy init`` writes it beside the CA; ``renew`` and ``revoke`` read and rewrite
it. Every configuration file is generated from it, so the description is the one place an
operator changes a fleet.
"""

from __future__ import annotations

import ipaddress
import json
import secrets
from dataclasses import asdict, dataclass, field
from typing import Any

from fleetlog.errors import FormatError
from fleetlog.wire.access import Role
from fleetlog.wire.access_profile import Identity, Profile, check_name
from fleetlog.wire.keys import check_root

__all__ = [
    "DEFAULT_PORT",
    "SHORE",
    "Fleet",
    "Machine",
    "Revoked",
    "parse_address",
]

FORMAT = 1
DEFAULT_PORT = 7447
#: the shore's name: its router is ``fleetlog:router:shore``, its tools ``fleetlog:operator:shore``
SHORE = "shore"


def parse_address(text: str, default_port: int) -> tuple[str, int]:
    """Split ``HOST[:PORT]`` (``[v6]:PORT`` for IPv6).

    Raises:
        FormatError: an empty host or a port that is not 1-65535.
    """
    host, port = text, default_port
    if text.startswith("["):
        end = text.find("]")
        if end < 0:
            msg = f"address {text!r} opens '[' without closing it"
            raise FormatError(msg)
        host, rest = text[1:end], text[end + 1 :]
        if rest:
            if not rest.startswith(":"):
                msg = f"address {text!r}: expected ':PORT' after ']'"
                raise FormatError(msg)
            port = _port(rest[1:], text)
    elif text.count(":") == 1:
        host, tail = text.split(":")
        port = _port(tail, text)
    if not host or any(c in host for c in "/#?* "):
        msg = f"address {text!r} has no usable host"
        raise FormatError(msg)
    return host, port


def _port(text: str, whole: str) -> int:
    if not text.isdigit() or not 0 < int(text) < 65536:
        msg = f"address {whole!r}: the port must be 1-65535"
        raise FormatError(msg)
    return int(text)


def is_loopback(host: str) -> bool:
    """Whether a host is a loopback address or localhost."""
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def endpoint(host: str, port: int) -> str:
    """A Zenoh TLS endpoint."""
    shown = f"[{host}]" if ":" in host else host
    return f"tls/{shown}:{port}"


@dataclass
class Machine:
    """A router's machine: the shore, or a vehicle.

    Attributes:
        name: ``shore`` or the vehicle's name.
        addresses: host names and IP addresses it is reached at (the first is dialled).
        port: the port its router listens on.
        zid: its router's Zenoh id, fixed so that other routers' configurations can name it.
    """

    name: str
    addresses: list[str] = field(default_factory=list)
    port: int = DEFAULT_PORT
    zid: str = ""

    def __post_init__(self) -> None:
        if not self.zid:
            self.zid = secrets.token_hex(8).lstrip("0") or "1"

    @property
    def local_only(self) -> bool:
        """Its router listens on loopback only (every address given is a loopback one)."""
        return bool(self.addresses) and all(is_loopback(a) for a in self.addresses)

    def listen(self) -> str:
        """The endpoint its router listens on."""
        if self.local_only:
            return endpoint(self.addresses[0], self.port)
        # IPv4's any-address: "[::]" fails to resolve on hosts without a global IPv6 address
        # (getaddrinfo's AI_ADDRCONFIG), which radio networks often are.
        return endpoint("0.0.0.0", self.port)

    def dial(self) -> str:
        """The endpoint others dial to reach its router."""
        if not self.addresses:
            msg = f"machine {self.name!r} has no address to be reached at"
            raise FormatError(msg)
        return endpoint(self.addresses[0], self.port)

    def local_dial(self) -> str:
        """The endpoint processes on the machine itself dial."""
        host = self.addresses[0] if self.local_only else "127.0.0.1"
        return endpoint(host, self.port)

    def cert_names(self) -> tuple[str, ...]:
        """The names its router's certificate must carry."""
        out = ["localhost", "127.0.0.1", "::1"]
        out.extend(a for a in self.addresses if a not in out)
        return tuple(out)


@dataclass
class Revoked:
    """A revoked common name: never granted anything again."""

    common_name: str
    when: str
    reason: str = ""


@dataclass
class Fleet:
    """The description of a fleet (``fleet.json``).

    Attributes:
        name: the fleet's name (in the CA's name).
        root: the key root.
        shore: the shore's machine.
        vehicles: each vehicle's machine.
        operators: operator names.
        replays: replay host names.
        generations: ``role:name`` → the identity's current generation (2 after one revoke).
        expiry: ``role:name`` → when its certificate expires (ISO 8601, UTC).
        replay_prefix: what replayed vehicles' names start with.
        replay_into: live vehicles that replay hosts may publish into.
        revoked: every common name ever revoked.
        etc: where each machine's files are installed (``/etc/fleetlog``); empty: they stay
            where they were generated (a fleet tried on one machine, tests, the demo).
    """

    name: str
    root: str
    shore: Machine
    vehicles: dict[str, Machine] = field(default_factory=dict)
    operators: list[str] = field(default_factory=list)
    replays: list[str] = field(default_factory=list)
    generations: dict[str, int] = field(default_factory=dict)
    expiry: dict[str, str] = field(default_factory=dict)
    replay_prefix: str = "sim_"
    replay_into: list[str] = field(default_factory=list)
    revoked: list[Revoked] = field(default_factory=list)
    etc: str = "/etc/fleetlog"

    def check(self) -> Fleet:
        """Validate names and the root.

        Raises:
            FormatError: a bad name, a duplicate, or a bad root.
        """
        check_root(self.root)
        for name in self.vehicles:
            check_name(name, "vehicle")
        for name in (*self.operators, *self.replays):
            check_name(name, "operator or replay host")
        if SHORE in self.vehicles:
            msg = f"a vehicle may not be named {SHORE!r}: the shore's router has that name"
            raise FormatError(msg)
        for name in self.replay_into:
            if name not in self.vehicles:
                msg = f"replays may go into vehicle {name!r}, which the fleet does not have"
                raise FormatError(msg)
        return self

    # -- identities

    def identity(self, role: Role, name: str) -> Identity:
        """The current identity of a holder."""
        return Identity(role, name, self.generations.get(f"{role.value}:{name}", 1))

    def holders(self) -> list[tuple[str, Identity]]:
        """Every certificate holder: (machine directory, identity), in a stable order."""
        out: list[tuple[str, Identity]] = [
            (SHORE, self.identity(Role.ROUTER, SHORE)),
            (SHORE, self.identity(Role.OPERATOR, SHORE)),
        ]
        for name in sorted(self.vehicles):
            out.append((f"vehicles/{name}", self.identity(Role.ROUTER, name)))
            out.append((f"vehicles/{name}", self.identity(Role.VEHICLE, name)))
        out.extend((f"operators/{n}", self.identity(Role.OPERATOR, n)) for n in self.operators)
        out.extend((f"replays/{n}", self.identity(Role.REPLAY, n)) for n in self.replays)
        return out

    def find(self, role: Role, name: str) -> tuple[str, Identity]:
        """The machine directory and identity of one holder.

        Raises:
            FormatError: the fleet has no such holder.
        """
        for where, who in self.holders():
            if who.role is role and who.name == name:
                return where, who
        known = ", ".join(f"{w.role.value} {w.name}" for _, w in self.holders())
        msg = f"the fleet has no {role.value} {name!r} (it has: {known})"
        raise FormatError(msg)

    def profile(self) -> Profile:
        """The access-control profile of the fleet's current identities."""
        revoked = {r.common_name for r in self.revoked}
        ids = tuple(w for _, w in self.holders() if w.common_name not in revoked)
        return Profile(self.root, ids, self.replay_prefix, tuple(self.replay_into))

    def routers(self) -> list[Machine]:
        """Every machine that runs a router: the shore, then the vehicles."""
        return [self.shore, *(self.vehicles[n] for n in sorted(self.vehicles))]

    # -- JSON

    def to_json(self) -> str:
        """The description as JSON text."""
        data = asdict(self)
        data = {"format": FORMAT, **data}
        return json.dumps(data, indent=2, sort_keys=False) + "\n"

    @classmethod
    def from_json(cls, text: str | bytes, where: str = "fleet.json") -> Fleet:
        """Read a description.

        Raises:
            FormatError: not a fleet description fleetlog wrote.
        """
        try:
            data = _fleet_dict(json.loads(text))
            data["shore"] = Machine(**data["shore"])
            data["vehicles"] = {k: Machine(**v) for k, v in data["vehicles"].items()}
            data["revoked"] = [Revoked(**r) for r in data["revoked"]]
            return cls(**data).check()
        except FormatError as err:
            raise FormatError(err.reason, where) from None
        except (ValueError, TypeError, KeyError, AttributeError) as err:
            msg = f"not a usable fleet description: {err}"
            raise FormatError(msg, where) from None


def _fleet_dict(data: Any) -> dict[str, Any]:
    if not isinstance(data, dict) or data.pop("format", None) != FORMAT:
        msg = "not a fleet description (format 1)"
        raise FormatError(msg)
    return data


def as_dict(value: Any) -> Any:
    """A dataclass as a dict (for tests)."""
    return asdict(value)
