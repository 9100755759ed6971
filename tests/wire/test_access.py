"""The security profile's access table, walked against docs/wire.md's key table.

Every key docs/wire.md lists must have a rule for every role, and the ``access_control`` the
routers run must give every role, message type and flow on that key the verdict the table
says: evaluated here with Zenoh's own key-expression inclusion (the test the routers make).
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest
import zenoh
from hypothesis import given
from hypothesis import strategies as st

from fleetlog.errors import FormatError
from fleetlog.wire.access import (
    DATA,
    DECLARATIONS,
    KEY_RULES,
    MESSAGES,
    Action,
    Flow,
    KeyRule,
    Role,
    grants_of,
    messages_of,
)
from fleetlog.wire.access_profile import (
    Identity,
    Profile,
    access_control,
    common_name,
    parse_common_name,
)

WIRE = Path(__file__).resolve().parents[2] / "docs" / "wire.md"
ROOT = "fleet"
PREFIX = "sim_"
IDS = (
    Identity(Role.VEHICLE, "alpha"),
    Identity(Role.VEHICLE, "bravo"),
    Identity(Role.OPERATOR, "ops"),
    Identity(Role.REPLAY, "sim"),
    Identity(Role.ROUTER, "shore"),
)
PROFILE = Profile(ROOT, IDS, PREFIX, ("bravo",))
ACL = access_control(PROFILE)
#: concrete stand-ins for the placeholders of docs/wire.md's keys
PLACEHOLDERS = {
    "<root>": ROOT,
    "<session>": "MOOSLog_1",
    "<name>": "a.alog",
    "VAR": "NAV_X",
    "ZID": "1f2e",
    "EID": "7",
}


def wire_keys() -> list[str]:
    """The keys in the table under '## Keys' of docs/wire.md."""
    text = WIRE.read_text(encoding="utf-8")
    section = text.split("\n## Keys\n", 1)[1].split("\n## ", 1)[0]
    keys = []
    for line in section.splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if len(cells) >= 2 and cells[1].startswith("`<root>/"):
            keys.append(cells[1].strip("`"))
    return keys


def concrete(wire_key: str, vehicle: str) -> str:
    """A concrete key of a wire.md key, for one vehicle."""
    parts = wire_key.split("/")
    parts[1] = vehicle
    out = []
    for part in parts:
        for placeholder, value in PLACEHOLDERS.items():
            if part == placeholder or part == placeholder.strip("<>"):
                part = value
        out.append(part)
    return "/".join(out)


def verdict(identity: Identity, flow: Flow, message: str, key: str) -> bool:
    """What the generated access_control decides: default deny, allow if a rule includes."""
    subject = f"{identity.role.value}:{identity.name}"
    policy = next(p for p in ACL["policies"] if p["subjects"] == [subject])
    rules = {r["id"]: r for r in ACL["rules"]}
    target = zenoh.KeyExpr(key)
    for rid in policy["rules"]:
        rule = rules[rid]
        if flow.value not in rule["flows"] or message not in rule["messages"]:
            continue
        if any(zenoh.KeyExpr(k).includes(target) for k in rule["key_exprs"]):
            return True
    return False


def expected(identity: Identity, flow: Flow, message: str, key: str) -> bool:
    """What the table says, derived without the generator: grants, then whose vehicle."""
    vehicle, tail = key.split("/", 2)[1], key.split("/", 2)[2]
    declaration = flow is Flow.EGRESS and message in DECLARATIONS
    for action in grants_of(identity.role, tail, declared=declaration):
        if (flow, message) not in messages_of(action):
            continue
        role = identity.role
        if role is Role.VEHICLE:
            # Only its own vehicle, except what is sent to it and carries nobody's data.
            if vehicle == identity.name or (flow is Flow.EGRESS and (flow, message) not in DATA):
                return True
        elif role is Role.REPLAY and action in (Action.PUBLISH, Action.SERVE, Action.TOKEN):
            if vehicle.startswith(PREFIX) or vehicle in PROFILE.replay_into:
                return True
        else:
            return True
    return False


def test_every_wire_key_has_a_rule_and_every_rule_a_wire_key() -> None:
    listed = wire_keys()
    assert len(listed) >= 10, "docs/wire.md's key table was not found"
    ruled = [rule.wire for rule in KEY_RULES]
    assert sorted(set(listed) - set(ruled)) == [], "keys in docs/wire.md without an access rule"
    assert sorted(set(ruled) - set(listed)) == [], "access rules for keys not in docs/wire.md"
    assert len(ruled) == len(set(ruled)), "a key has two rules"


@pytest.mark.parametrize("rule", KEY_RULES, ids=lambda r: r.wire)
def test_every_rule_names_every_role(rule: KeyRule) -> None:
    assert set(rule.grants) == set(Role)
    for vehicle in ("alpha", "sim_alpha"):
        key = concrete(rule.wire, vehicle).split("/", 2)[2]
        assert zenoh.KeyExpr(rule.key).includes(zenoh.KeyExpr(key)), (rule.key, key)


def test_a_rule_without_a_role_is_refused() -> None:
    with pytest.raises(FormatError, match="names no grant for router"):
        KeyRule(
            "var/**", "<root>/V/var/VAR", {r: frozenset() for r in Role if r is not Role.ROUTER}
        )


@pytest.mark.parametrize("wire_key", wire_keys())
def test_walk_every_key_role_message_and_flow(wire_key: str) -> None:
    wrong = []
    for vehicle in ("alpha", "bravo", "sim_alpha"):
        key = concrete(wire_key, vehicle)
        for identity in IDS:
            for flow in Flow:
                for message in MESSAGES:
                    got = verdict(identity, flow, message, key)
                    want = expected(identity, flow, message, key)
                    if got != want:
                        wrong.append(
                            f"{identity.common_name} {flow.value} {message} {key}:"
                            f" {'allowed' if got else 'denied'}, table says"
                            f" {'allow' if want else 'deny'}"
                        )
    assert wrong == []


@pytest.mark.parametrize(
    ("who", "flow", "message", "key", "allowed"),
    [
        # what the fleet's own tools send, wildcards included
        (IDS[0], Flow.INGRESS, "declare_subscriber", "fleet/alpha/var/*", True),
        (IDS[0], Flow.INGRESS, "declare_subscriber", "fleet/alpha/var/*/@adv/pub/**", True),
        (IDS[0], Flow.INGRESS, "declare_queryable", "fleet/alpha/@fleetlog/file/*/*", True),
        (IDS[0], Flow.INGRESS, "liveliness_query", "fleet/alpha/@fleetlog/recorder", True),
        (IDS[0], Flow.EGRESS, "query", "fleet/*/@fleetlog/latest", True),
        (IDS[0], Flow.EGRESS, "declare_subscriber", "fleet/*/var/**", True),
        (IDS[2], Flow.INGRESS, "query", "fleet/*/@fleetlog/latest", True),
        (IDS[2], Flow.INGRESS, "liveliness_query", "fleet/*/@fleetlog/recorder", True),
        (IDS[2], Flow.INGRESS, "declare_subscriber", "fleet/*/var/**", True),
        (IDS[2], Flow.EGRESS, "declare_subscriber", "fleet/alpha/var/*", True),
        (IDS[4], Flow.EGRESS, "query", "fleet/*/@fleetlog/latest", True),
        (IDS[2], Flow.INGRESS, "query", "fleet/*/@fleetlog/**", False),
        # the pitfalls: `**` never crosses a verbatim chunk, another vehicle is another
        (IDS[2], Flow.INGRESS, "declare_subscriber", "fleet/**", False),
        (IDS[2], Flow.INGRESS, "query", "fleet/**", False),
        (IDS[0], Flow.INGRESS, "liveliness_query", "fleet/*/@fleetlog/recorder", False),
        (IDS[1], Flow.INGRESS, "declare_queryable", "fleet/alpha/@fleetlog/**", False),
        (IDS[1], Flow.INGRESS, "put", "fleet/alpha/var/NAV_X", False),
        (IDS[1], Flow.EGRESS, "put", "fleet/alpha/var/NAV_X", False),
        (IDS[1], Flow.EGRESS, "liveliness_token", "fleet/alpha/@fleetlog/recorder", False),
        (IDS[3], Flow.INGRESS, "put", "fleet/alpha/var/NAV_X", False),
        (IDS[3], Flow.INGRESS, "put", "fleet/sim_alpha/var/NAV_X", True),
        (IDS[3], Flow.INGRESS, "put", "fleet/bravo/var/NAV_X", True),  # replay_into
        (IDS[3], Flow.INGRESS, "query", "fleet/alpha/@fleetlog/control", False),
        (IDS[2], Flow.INGRESS, "put", "fleet/alpha/var/NAV_X", False),
        (IDS[2], Flow.INGRESS, "put", "fleet/alpha/var/PLOGGER_CMD", True),
    ],
)
def test_what_the_tools_send(
    who: Identity, flow: Flow, message: str, key: str, allowed: bool
) -> None:
    assert verdict(who, flow, message, key) is allowed


def test_the_profile_survives_zenoh_pitfalls() -> None:
    assert ACL["enabled"] is True
    assert ACL["default_permission"] == "deny"
    for subject in ACL["subjects"]:
        # Exactly one exact common name per subject: no interface-, protocol- or
        # "any certificate" subjects, and names no public CA issues.
        assert set(subject) == {"id", "cert_common_names"}
        (cn,) = subject["cert_common_names"]
        assert cn.startswith("fleetlog:")
        assert "*" not in cn
    for rule in ACL["rules"]:
        assert rule["permission"] == "allow"
        for key in rule["key_exprs"]:
            zenoh.KeyExpr(key)  # valid
            assert key != f"{ROOT}/**"
            assert not key.startswith("**")


def test_the_configuration_loads_in_zenoh() -> None:
    import json

    zenoh.Config.from_json5(json.dumps({"access_control": ACL}))


def test_common_names_round_trip() -> None:
    for role in Role:
        for generation in (1, 2, 17):
            cn = common_name(role, "alpha-1.b_c", generation)
            assert parse_common_name(cn) == Identity(role, "alpha-1.b_c", generation)


@pytest.mark.parametrize(
    "cn",
    [
        "alpha",
        "fleetlog.example.org",
        "fleetlog:vehicle",
        "fleetlog:admin:alpha",
        "fleetlog:vehicle:",
        "fleetlog:vehicle:*",
        "fleetlog:vehicle:alpha:1",
        "fleetlog:vehicle:alpha:x",
        "fleetlog:vehicle:alpha/b",
        "fleetlog:vehicle:-a",
    ],
)
def test_names_that_are_not_identities(cn: str) -> None:
    with pytest.raises(FormatError):
        parse_common_name(cn)


@given(st.text(max_size=80))
def test_parse_common_name_takes_anything(text: str) -> None:
    try:
        who = parse_common_name(text)
    except FormatError:
        return
    assert who.common_name == text
    assert re.fullmatch(r"fleetlog:[a-z]+:[A-Za-z0-9][A-Za-z0-9_.-]*(:\d+)?", text)
