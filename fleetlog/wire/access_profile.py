"""A fleet's identities and the access-control section its routers run, built from the key table.

An :class:`Identity` is a certificate common name in a form no public certificate authority
issues (``fleetlog:vehicle:alpha``, ``fleetlog:vehicle:bravo:2`` after a revocation;
:func:`common_name`, :func:`parse_common_name`). A :class:`Profile` lists a fleet's identities,
and :func:`access_control` turns it and the table of :mod:`fleetlog.wire.access` (who may do
what on which key) into the ``access_control`` section of a Zenoh configuration, the same
for every router of the fleet: default deny, one subject per exact common name.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Any

from fleetlog.errors import FormatError
from fleetlog.moos.patterns import name_to_chunk
from fleetlog.wire.access import (
    DATA,
    DECLARATIONS,
    KEY_RULES,
    Action,
    Flow,
    Role,
    messages_of,
)

__all__ = [
    "CN_PREFIX",
    "Identity",
    "Profile",
    "access_control",
    "check_name",
    "common_name",
    "parse_common_name",
]


#: every common name of the fleet starts so; no public CA issues names with colons
CN_PREFIX = "fleetlog:"
_NAME_RE = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]{0,62}$")


@dataclass(frozen=True, slots=True)
class Identity:
    """A certificate's identity: its role, its name, and its generation.

    A revoked identity's name gets a new generation (``fleetlog:vehicle:bravo:2``): Zenoh has
    no revocation list, so the old certificate, which stays valid until it expires, must no
    longer match any rule, while the new one does.
    """

    role: Role
    name: str
    generation: int = 1

    @property
    def common_name(self) -> str:
        """The certificate's common name."""
        return common_name(self.role, self.name, self.generation)


def common_name(role: Role, name: str, generation: int = 1) -> str:
    """Return the common name of an identity (``fleetlog:vehicle:alpha``).

    Raises:
        FormatError: the name is not 1-63 letters, digits, ``_``, ``.`` or ``-``.
    """
    check_name(name, role.value)
    tail = f":{generation}" if generation > 1 else ""
    return f"{CN_PREFIX}{role.value}:{name}{tail}"


def check_name(name: str, what: str) -> str:
    """Validate the name of a vehicle, operator, replay host or router.

    Raises:
        FormatError: the name is not 1-63 letters, digits, ``_``, ``.`` or ``-``, starting
            with a letter or digit.
    """
    if not _NAME_RE.match(name):
        msg = (
            f"{what} name {name!r} must be 1-63 letters, digits, '_', '.' or '-',"
            " starting with a letter or a digit"
        )
        raise FormatError(msg)
    return name


def parse_common_name(cn: str) -> Identity:
    """Read an identity from a certificate's common name.

    Raises:
        FormatError: the name is not a fleetlog identity.
    """
    parts = cn.split(":")
    if len(parts) not in (3, 4) or parts[0] + ":" != CN_PREFIX:
        msg = f"certificate name {cn!r} is not a fleetlog identity (fleetlog:ROLE:NAME)"
        raise FormatError(msg)
    try:
        role = Role(parts[1])
    except ValueError:
        roles = ", ".join(r.value for r in Role)
        msg = f"certificate name {cn!r} has no fleetlog role ({roles})"
        raise FormatError(msg) from None
    generation = 1
    if len(parts) == 4:
        if not parts[3].isdigit() or int(parts[3]) < 2:
            msg = f"certificate name {cn!r} has a bad generation {parts[3]!r}"
            raise FormatError(msg)
        generation = int(parts[3])
    check_name(parts[2], role.value)
    return Identity(role, parts[2], generation)


@dataclass(frozen=True)
class Profile:
    """The identities of a fleet and what the security profile grants them.

    Attributes:
        root: the key root.
        identities: every identity that is not revoked.
        replay_prefix: replayed vehicles' names start with it (``sim_alpha``).
        replay_into: live vehicles that replay hosts may publish into.
    """

    root: str
    identities: tuple[Identity, ...]
    replay_prefix: str = "sim_"
    replay_into: tuple[str, ...] = ()

    def of(self, role: Role) -> list[Identity]:
        """The identities of one role, by name."""
        return sorted((i for i in self.identities if i.role is role), key=lambda i: i.name)


def _vehicle_chunks(profile: Profile, role: Role, who: Identity, writing: bool) -> list[str]:
    """The key chunks standing for "which vehicle" in a role's rules."""
    if role is Role.VEHICLE:
        return [name_to_chunk(who.name)]
    if role is Role.REPLAY and writing:
        prefix = name_to_chunk(profile.replay_prefix)
        return [f"{prefix}$*", *(name_to_chunk(v) for v in profile.replay_into)]
    return ["*"]


def _rules_for(profile: Profile, who: Identity) -> dict[tuple[Flow, str], set[str]]:
    """Every (flow, message) → key expressions one identity is allowed."""
    allowed: dict[tuple[Flow, str], set[str]] = {}
    role = who.role
    for rule in KEY_RULES:
        for action in rule.grants[role]:
            writing = action in (Action.PUBLISH, Action.SERVE, Action.TOKEN)
            for flow, message in messages_of(action):
                if role is Role.VEHICLE and (flow, message) not in DATA and flow is Flow.EGRESS:
                    chunks = ["*"]
                else:
                    chunks = _vehicle_chunks(profile, role, who, writing)
                declaration = flow is Flow.EGRESS and message in DECLARATIONS
                key = rule.declared if declaration else rule.key
                keys = allowed.setdefault((flow, message), set())
                keys.update(f"{profile.root}/{chunk}/{key}" for chunk in chunks)
    return allowed


def access_control(profile: Profile) -> dict[str, Any]:
    """Build the ``access_control`` section every router of the fleet runs.

    Default deny; one subject per identity (its exact common name), one rule per identity,
    flow and message type, and one policy tying them. Nothing is granted to a subject
    without a common name, nor to an interface or a protocol alone.
    """
    rules: list[dict[str, Any]] = []
    subjects: list[dict[str, Any]] = []
    policies: list[dict[str, Any]] = []
    for role in Role:
        for who in profile.of(role):
            sid = f"{role.value}:{who.name}"
            subjects.append({"id": sid, "cert_common_names": [who.common_name]})
            ids: list[str] = []
            for (flow, message), keys in sorted(
                _rules_for(profile, who).items(), key=lambda kv: (kv[0][0].value, kv[0][1])
            ):
                rid = f"{sid}:{flow.value}:{message}"
                rules.append(
                    {
                        "id": rid,
                        "permission": "allow",
                        "flows": [flow.value],
                        "messages": [message],
                        "key_exprs": sorted(keys),
                    }
                )
                ids.append(rid)
            policies.append({"id": sid, "rules": ids, "subjects": [sid]})
    return {
        "enabled": True,
        "default_permission": "deny",
        "rules": rules,
        "subjects": subjects,
        "policies": policies,
    }
