"""Who may do what on which key: the access-control table of the security profile.

Every key of ``docs/wire.md`` has one :class:`KeyRule` in :data:`KEY_RULES`, and every rule
names, for every :class:`Role`, the :class:`Action` set that role may take on the key (an
empty set is a rule too: "nothing").
:func:`fleetlog.wire.access_profile.access_control` turns the table into the
``access_control`` section of a Zenoh configuration, the same for every router of the fleet,
so that a stranger reaching any router, a vehicle's included, is refused alike.

Adding a key: add its row to docs/wire.md's key table and a :class:`KeyRule` here, with all
four roles; ``tests/wire/test_access.py`` walks the table and fails on a key without one.

Identities (:mod:`fleetlog.wire.access_profile`) are certificate common names in a form no
public certificate authority issues (``fleetlog:vehicle:alpha``): Zenoh's TLS layer also
trusts the public WebPKI roots beside the fleet's CA (eclipse-zenoh/zenoh#2764), so a name a
public CA could sign must never be granted anything, and no rule grants anything to "any
valid certificate".

Zenoh checks a message against a rule by *inclusion*: a rule on ``fleet/*/var/**`` allows a
subscription to ``fleet/*/var/**`` or ``fleet/alpha/var/NAV_X``, but ``fleet/**`` does not
include ``fleet/alpha/@fleetlog/status`` (``@fleetlog`` is a verbatim chunk). So each rule's
key is written per kind of key, never as one ``fleet/**``.
"""

from __future__ import annotations

import enum
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field

from fleetlog.errors import FormatError

__all__ = [
    "DATA",
    "DECLARATIONS",
    "KEY_RULES",
    "MESSAGES",
    "Action",
    "Flow",
    "KeyRule",
    "Role",
    "access_matrix",
    "grants_of",
    "messages_of",
]


class Role(enum.Enum):
    """What a certificate is for; the middle part of its common name."""

    #: the processes of one vehicle (recorder, bridge, apps), on that vehicle's keys
    VEHICLE = "vehicle"
    #: a person or a shore service (fleet, fetch, query, collect, poke of commands)
    OPERATOR = "operator"
    #: a replay host: publishes only under the replay prefix (and vehicles granted to it)
    REPLAY = "replay"
    #: a Zenoh router of the fleet: it forwards what the edge routers let in
    ROUTER = "router"


class Action(enum.Enum):
    """What a role may do on a key; each is a set of Zenoh messages (:func:`messages_of`)."""

    PUBLISH = "publish"
    SUBSCRIBE = "subscribe"
    SERVE = "serve"
    ASK = "ask"
    TOKEN = "token"
    WATCH = "watch"


class Flow(enum.Enum):
    """Zenoh's ACL flows, seen from the router: ingress from the subject, egress to it."""

    INGRESS = "ingress"
    EGRESS = "egress"


#: every message type Zenoh's access control filters
MESSAGES = (
    "put",
    "delete",
    "declare_subscriber",
    "query",
    "reply",
    "declare_queryable",
    "liveliness_token",
    "liveliness_query",
    "declare_liveliness_subscriber",
)

# What each action lets through, and in which flow. Egress declarations are how a publisher
# or a querier learns that someone listens (a publisher's matching status, a short-lived
# poke waiting for the recorder), so each action that sends gets the matching one. Nothing
# in fleetlog deletes, so no action grants "delete".
_MESSAGES: dict[Action, tuple[tuple[Flow, str], ...]] = {
    Action.PUBLISH: ((Flow.INGRESS, "put"), (Flow.EGRESS, "declare_subscriber")),
    Action.SUBSCRIBE: ((Flow.INGRESS, "declare_subscriber"), (Flow.EGRESS, "put")),
    Action.SERVE: (
        (Flow.INGRESS, "declare_queryable"),
        (Flow.INGRESS, "reply"),
        (Flow.EGRESS, "query"),
    ),
    Action.ASK: (
        (Flow.INGRESS, "query"),
        (Flow.EGRESS, "reply"),
        (Flow.EGRESS, "declare_queryable"),
    ),
    Action.TOKEN: ((Flow.INGRESS, "liveliness_token"),),
    Action.WATCH: (
        (Flow.INGRESS, "liveliness_query"),
        (Flow.INGRESS, "declare_liveliness_subscriber"),
        (Flow.EGRESS, "liveliness_token"),
    ),
}

#: messages that carry a vehicle's data, an answer or a token to the subject: for a vehicle only its
#: own keys. The others (queries and declarations sent *to* the subject) may come with a
#: wildcard where the vehicle is (``fleet/*/@fleetlog/latest`` asks every vehicle), and Zenoh
#: allows a message only if the rule's key includes the message's, so those are granted on
#: every vehicle's key: a vehicle learns that someone asks, never someone else's data.
DATA = frozenset({(Flow.EGRESS, "put"), (Flow.EGRESS, "reply"), (Flow.EGRESS, "liveliness_token")})


#: declarations the router sends a subject: on the rule's ``declared`` expression
DECLARATIONS = frozenset({"declare_subscriber", "declare_queryable"})


def messages_of(action: Action) -> tuple[tuple[Flow, str], ...]:
    """Return the (flow, Zenoh message) pairs an action allows."""
    return _MESSAGES[action]


P, S, SV, A, T, W = (
    Action.PUBLISH,
    Action.SUBSCRIBE,
    Action.SERVE,
    Action.ASK,
    Action.TOKEN,
    Action.WATCH,
)
ALL = frozenset(Action)
NOTHING: frozenset[Action] = frozenset()


@dataclass(frozen=True)
class KeyRule:
    """The rule of one key of docs/wire.md.

    Attributes:
        key: the key expression under ``<root>/<V>/`` (``var/**``, ``@fleetlog/status``).
        wire: the key as docs/wire.md's key table writes it (``<root>/V/var/VAR``).
        grants: for every role, what it may do on the key.
        declared: the widest key expression a subscriber or queryable of this key may be
            declared on (the recorder subscribes to ``var/*``, not to ``var/PLOGGER_CMD``):
            a publisher learns of subscribers, a querier of queryables, through these
            declarations, and Zenoh passes one only if a rule's key includes it.
    """

    key: str
    wire: str
    grants: Mapping[Role, frozenset[Action]] = field(default_factory=dict)
    declared: str = ""

    def __post_init__(self) -> None:
        missing = [role.value for role in Role if role not in self.grants]
        if missing:
            msg = f"access rule for {self.wire} names no grant for {', '.join(missing)}"
            raise FormatError(msg)
        if not self.declared:
            object.__setattr__(self, "declared", self.key)


def _rule(
    key: str,
    wire: str,
    *,
    vehicle: Iterable[Action],
    operator: Iterable[Action],
    replay: Iterable[Action],
    router: Iterable[Action] = ALL,
    declared: str = "",
) -> KeyRule:
    return KeyRule(
        key,
        wire,
        {
            Role.VEHICLE: frozenset(vehicle),
            Role.OPERATOR: frozenset(operator),
            Role.REPLAY: frozenset(replay),
            Role.ROUTER: frozenset(router),
        },
        declared or key,
    )


#: The table. A vehicle's role is on its own keys only; an operator's and a replay host's
#: reading actions (subscribe, ask, watch) are on every vehicle; a replay host's writing
#: actions (publish, serve, token) only on the replay prefix's vehicles and on the vehicles
#: the fleet grants replays into (Profile.replay_into). Routers forward everything the edge
#: let in.
KEY_RULES: tuple[KeyRule, ...] = (
    _rule(
        "var/**",
        "<root>/V/var/VAR",
        vehicle={P, S},
        operator={S},
        replay={P},
    ),
    _rule(
        "var/PLOGGER_CMD",
        "<root>/V/var/PLOGGER_CMD",
        vehicle={P, S},
        operator={P, S},
        replay={P},
        declared="var/**",
    ),
    _rule(
        "var/LOGGER_RESTART",
        "<root>/V/var/LOGGER_RESTART",
        vehicle={P, S},
        operator={P, S},
        replay={P},
        declared="var/**",
    ),
    _rule(
        "var/*/@adv/**",
        "<root>/V/var/VAR/@adv/pub/ZID/EID/_",
        vehicle={P, S},
        operator=NOTHING,
        replay={P},
    ),
    _rule(
        "@fleetlog/recorder",
        "<root>/V/@fleetlog/recorder",
        vehicle={T, W},
        operator={W},
        replay={W},
    ),
    _rule(
        "@fleetlog/serve",
        "<root>/V/@fleetlog/serve",
        vehicle={T, W},
        operator={W},
        replay={W},
    ),
    _rule(
        "@fleetlog/status",
        "<root>/V/@fleetlog/status",
        vehicle={SV, A},  # a vehicle app confirms delivery by asking its recorder
        operator={A},
        replay={A},
    ),
    _rule(
        "@fleetlog/control",
        "<root>/V/@fleetlog/control",
        vehicle={SV},
        operator={A},
        replay=NOTHING,
    ),
    _rule(
        # prune deletes the sessions the shore acknowledged: granted apart from the other
        # commands, so a fleet may keep it from a role (collect --prune-after-collect)
        "@fleetlog/control/prune",
        "<root>/V/@fleetlog/control/prune",
        vehicle={SV},
        operator={A},
        replay=NOTHING,
    ),
    _rule(
        "@fleetlog/latest",
        "<root>/V/@fleetlog/latest",
        vehicle={SV},
        operator={A},
        replay={A},
    ),
    _rule(
        "@fleetlog/sessions",
        "<root>/V/@fleetlog/sessions",
        vehicle={SV},
        operator={A},
        replay={A},
    ),
    _rule(
        "@fleetlog/file/*/*",
        "<root>/V/@fleetlog/file/<session>/<name>",
        vehicle={SV},
        operator={A},
        replay={A},
    ),
    _rule(
        "@fleetlog/grep/*",
        "<root>/V/@fleetlog/grep/<session>",
        vehicle={SV},
        operator={A},
        replay={A},
    ),
    _rule(
        "@fleetlog/replay",
        "<root>/V/@fleetlog/replay",
        vehicle=NOTHING,
        operator={W},  # fleetlog replay-ctl finds running replays by their tokens
        replay={T, W},
    ),
    _rule(
        "@fleetlog/replay/control",
        "<root>/V/@fleetlog/replay/control",
        vehicle=NOTHING,
        operator={A},
        replay={SV},
    ),
    _rule(
        "@fleetlog/replay/status",
        "<root>/V/@fleetlog/replay/status",
        vehicle=NOTHING,
        operator={S, A},
        replay={P, SV},
    ),
)

_READING = frozenset({Action.SUBSCRIBE, Action.ASK, Action.WATCH})


def grants_of(role: Role, key: str, *, declared: bool = False) -> frozenset[Action]:
    """What a role may do on a key under ``<root>/<V>/`` (union of the rules that match it).

    ``key`` is matched literally against each rule's key expression, with ``*`` one chunk and
    ``**`` any number of chunks not starting with ``@`` (Zenoh's rule for verbatim chunks).
    With ``declared``, against the expressions declarations may use (``KeyRule.declared``).
    """
    out: set[Action] = set()
    for rule in KEY_RULES:
        pattern = rule.declared if declared else rule.key
        if _includes(pattern.split("/"), key.split("/")):
            out |= rule.grants[role]
    return frozenset(out)


def _includes(pattern: list[str], chunks: list[str]) -> bool:
    if not pattern:
        return not chunks
    head, rest = pattern[0], pattern[1:]
    if head == "**":
        for i in range(len(chunks) + 1):
            if any(c.startswith("@") for c in chunks[:i]):
                break
            if _includes(rest, chunks[i:]):
                return True
        return False
    if not chunks:
        return False
    chunk = chunks[0]
    ok = not chunk.startswith("@") if head == "*" else head == chunk
    return ok and _includes(rest, chunks[1:])


def access_matrix() -> str:
    """The table as Markdown, for docs/deploy.md (a test keeps the two the same)."""
    roles = (Role.VEHICLE, Role.OPERATOR, Role.REPLAY, Role.ROUTER)
    head = "| key | vehicle (its own keys) | operator | replay host | router |"
    lines = [head, "|---|---|---|---|---|"]
    for rule in KEY_RULES:
        cells = []
        for role in roles:
            actions = rule.grants[role]
            if actions == ALL:
                cells.append("all")
            else:
                names = [a.value for a in Action if a in actions]
                cells.append(", ".join(names) if names else "—")
        lines.append(f"| `{rule.wire}` | " + " | ".join(cells) + " |")
    return "\n".join(lines)
