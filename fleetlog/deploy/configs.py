"""The Zenoh configurations of a fleet's machines, as JSON5 (the security profile).

Every router (the shore's, each vehicle's) runs the same access control; every link is TLS
with mutual authentication against the fleet's CA; nothing scouts; only ``tls/`` endpoints
listen. The values that differ from Zenoh's defaults are chosen for a radio link that drops,
crawls and has little bandwidth, and say why in the files themselves.
"""

from __future__ import annotations

from pathlib import PurePosixPath
from typing import Any

from fleetlog.deploy.fleet import SHORE, Fleet, Machine
from fleetlog.deploy.json5 import render
from fleetlog.wire.access_profile import access_control

__all__ = [
    "CA_FILE",
    "client_config",
    "example_configs",
    "router_config",
    "settings_toml",
]

CA_FILE = "ca.pem"
ROUTER_CERT, ROUTER_KEY = "router.pem", "router.key"

#: how long a silent link lives: 4 keep-alives per lease; a radio that fades for a few seconds
#: keeps its session, a dead one is noticed within 15 s
LEASE_MS = 15000
#: how long a blocked message waits for the link before Zenoh closes it (Zenoh: 5 s): at
#: 1 Mbit/s with 5 % loss a busy link can hold a batch longer than that
BLOCK_CLOSE_US = 30_000_000
#: connection and TLS handshakes over a 200 ms, lossy link
OPEN_TIMEOUT_MS = 30000
#: the urgent radio link's socket send buffer (bytes): what the kernel holds is sent in
#: order, so a command's answer waits behind all of it. Linux's default grows to megabytes
#: (tens of seconds at 1 Mbit/s); this is a fraction of a second.
RADIO_SNDBUF = 16384
#: the shore router's batches (bytes; each link takes the smaller of its two ends'): a batch
#: goes out whole, so a command's answer waits for the one being sent: 0.13 s at 1 Mbit/s
#: instead of 0.5 s for Zenoh's 64 KiB. Only links to the shore are affected; a vehicle's
#: own (loopback) links keep Zenoh's.
SHORE_BATCH = 16384
#: two links across the radio, by Zenoh priority (0 control ... 7 background): control,
#: commands and status (interactive) on one, with a small send buffer; data and bulk
#: transfers (fetch ranges and grep ask at background) on the other, with the kernel's: the
#: TCP buffers and retransmissions of a fetch never delay a command
URGENT_PRIORITIES = "0-4"
BULK_PRIORITIES = "5-7"
#: links per transport each router admits: the two above
MAX_LINKS = 2
#: reconnect: first after 1 s, backing off to every 8 s
RETRY = {"period_init_ms": 1000, "period_max_ms": 8000, "period_increase_factor": 2}


def _path(fleet: Fleet, machine_dir: str, base: str, name: str) -> str:
    etc = fleet.etc or str(PurePosixPath(base) / machine_dir)
    return str(PurePosixPath(etc) / name)


def _common(
    fleet: Fleet, machine_dir: str, base: str, cert: str, key: str, *, listen: bool
) -> dict[str, Any]:
    """Scouting off, TLS only, mutual TLS: the part of every configuration that is the same."""
    tls: dict[str, Any] = {
        "root_ca_certificate": _path(fleet, machine_dir, base, CA_FILE),
        "enable_mtls": True,
        "connect_certificate": _path(fleet, machine_dir, base, cert),
        "connect_private_key": _path(fleet, machine_dir, base, key),
        "verify_name_on_connect": True,
        "close_link_on_expiration": True,
    }
    if listen:
        tls["listen_certificate"] = _path(fleet, machine_dir, base, cert)
        tls["listen_private_key"] = _path(fleet, machine_dir, base, key)
    return {
        "scouting": {"multicast": {"enabled": False}, "gossip": {"enabled": False}},
        "transport": {
            "shared_memory": {"enabled": False},
            "unicast": {
                "open_timeout": OPEN_TIMEOUT_MS,
                "accept_timeout": OPEN_TIMEOUT_MS,
                "max_links": MAX_LINKS,
            },
            "link": {
                "protocols": ["tls"],
                "tx": {
                    "lease": LEASE_MS,
                    "keep_alive": 4,
                    "queue": {
                        "congestion_control": {"block": {"wait_before_close": BLOCK_CLOSE_US}}
                    },
                },
                "tls": tls,
            },
        },
    }


_COMMON_NOTES = {
    "scouting": "No multicast or gossip scouting: peers that find each other connect around the\n"
    "routers' access control (eclipse-zenoh/zenoh#2137).",
    "transport/link/protocols": "TLS links only: nothing is opened or accepted in clear.",
    "transport/shared_memory/enabled": "Everything through the TLS links: no shared-memory"
    " shortcut around them\n(two machines never share memory; the demo's namespaces do).",
    "transport/link/tx/lease": "A radio that fades for a few seconds keeps its session.",
    "transport/link/tx/queue/congestion_control/block/wait_before_close": "A slow, lossy link"
    " can hold a batch longer than Zenoh's 5 s before closing it.",
    "transport/link/tls/enable_mtls": "Mutual TLS: both ends show a certificate of the fleet's CA.",
    "transport/link/tls/root_ca_certificate": "The fleet's CA. Zenoh also trusts the public WebPKI"
    " roots (eclipse-zenoh/zenoh#2764):\naccess control grants only fleetlog:ROLE:NAME common"
    " names, which no public CA issues.",
    "transport/link/tls/close_link_on_expiration": "An expired certificate ends its links.",
}


def router_config(fleet: Fleet, machine: Machine, base: str) -> str:
    """The router configuration of the shore or of a vehicle, as JSON5.

    Args:
        fleet: the fleet.
        machine: the shore or a vehicle.
        base: the fleet directory (used when the fleet's files stay where they were made).
    """
    is_shore = machine.name == SHORE
    machine_dir = SHORE if is_shore else f"vehicles/{machine.name}"
    conf: dict[str, Any] = {
        "id": machine.zid,
        "mode": "router",
        "metadata": {"name": f"fleetlog router {machine.name}", "fleet": fleet.name},
        "listen": {"endpoints": [machine.listen()]},
    }
    notes = dict(_COMMON_NOTES)
    notes["id"] = "Fixed, so that the other routers' configurations can name this one."
    if is_shore:
        conf["connect"] = {"endpoints": []}
        notes["connect"] = "The vehicles' routers dial in; the shore dials nobody."
    else:
        conf["connect"] = {
            "endpoints": [
                f"{fleet.shore.dial()}?prio={URGENT_PRIORITIES}#so_sndbuf={RADIO_SNDBUF}",
                f"{fleet.shore.dial()}?prio={BULK_PRIORITIES}",
            ],
            "timeout_ms": -1,
            "exit_on_failure": False,
            "retry": RETRY,
        }
        notes["connect"] = (
            "Only this router crosses the radio: it dials the shore's router and keeps retrying"
            "\nin the background, whatever the link does. A small socket send buffer on the"
            "\nradio: what the kernel holds goes out in order, whatever Zenoh's priorities."
        )
    conf.update(_common(fleet, machine_dir, base, ROUTER_CERT, ROUTER_KEY, listen=True))
    if is_shore:
        conf["transport"]["link"]["tx"]["batch_size"] = SHORE_BATCH
        notes["transport/link/tx/batch_size"] = (
            "Small batches on the shore's links (each link takes the smaller of its two ends'):"
            "\na command's answer waits at most for one batch on a slow radio."
        )
    if not is_shore:
        # What the shore subscribes to must never stall the vehicle: data put with BLOCK
        # congestion control (every variable a vehicle app publishes) would otherwise wait
        # for the radio, holding up the app and, behind it, the recorder.
        conf["qos"] = {
            "network": [
                {
                    "id": "radio-never-blocks-the-vehicle",
                    "zids": [fleet.shore.zid],
                    "messages": ["put"],
                    "flows": ["egress"],
                    "overwrite": {"congestion_control": "drop"},
                }
            ]
        }
        notes["qos"] = (
            "Variables sent to the shore are dropped, not waited for, when the radio is full:"
            "\na vehicle app (and the recorder behind it) never waits for the radio."
        )
    conf["access_control"] = access_control(fleet.profile())
    notes["access_control"] = (
        "The same on every router of the fleet: generated by fleetlog deploy from the key"
        "\ntable of docs/wire.md. Default deny; each certificate common name gets its rules."
    )
    header = (
        f"Zenoh router of {machine.name} in fleet {fleet.name!r}: written by fleetlog deploy."
        "\nRun it with `fleetlog router -c THIS_FILE` or `zenohd -c THIS_FILE` (zenohd 1.10.2)."
    )
    return render(conf, notes, header)


def client_config(fleet: Fleet, machine_dir: str, cert: str, key: str, base: str) -> str:
    """The configuration of the fleetlog processes on one machine, as JSON5.

    On a vehicle (and on the shore) the processes reach the router on the same machine; an
    operator's or replay host's reach the shore's router.

    Args:
        fleet: the fleet.
        machine_dir: ``shore``, ``vehicles/NAME``, ``operators/NAME`` or ``replays/NAME``.
        cert: the certificate's file name.
        key: the key's file name.
        base: the fleet directory.
    """
    notes = dict(_COMMON_NOTES)
    if machine_dir.startswith("vehicles/"):
        target = fleet.vehicles[machine_dir.split("/", 1)[1]].local_dial()
        notes["mode"] = (
            "A client of this vehicle's router. `fleetlog record` opens as a peer that dials"
            "\nthe same router in the background instead, so that it records from its first"
            "\nsecond when the router is not up yet (boot order, a router restart)."
        )
    elif machine_dir == SHORE:
        target = fleet.shore.local_dial()
        notes["mode"] = "A client of the shore's router, on this machine."
    else:
        target = fleet.shore.dial()
        notes["mode"] = "A client of the shore's router."
    conf: dict[str, Any] = {
        "mode": "client",
        "connect": {"endpoints": [target]},
        "listen": {"endpoints": []},
    }
    notes["listen"] = "Nothing listens here, whatever mode a command chooses."
    common = _common(fleet, machine_dir, base, cert, key, listen=False)
    conf.update(common)
    header = (
        f"Zenoh configuration of the fleetlog processes on {machine_dir} in fleet"
        f" {fleet.name!r}:\nwritten by fleetlog deploy; installed as /etc/fleetlog/zenoh.json5,"
        " every fleetlog command\non the machine uses it without -c."
    )
    return render(conf, notes, header)


def settings_toml(fleet: Fleet, vehicle: str | None) -> str:
    """Fleetlog's own settings for a machine (``fleetlog.toml``)."""
    lines = [
        f"# fleetlog settings of fleet {fleet.name!r}: written by fleetlog deploy.",
        f'root = "{fleet.root}"',
    ]
    if vehicle is not None:
        lines.append(f'vehicle = "{vehicle}"')
    return "\n".join(lines) + "\n"


def example_configs() -> dict[str, str]:
    """The configurations of an example fleet, as shipped in deploy/zenoh/ (a test keeps them).

    Vehicles alpha and bravo, a shore at shore.example.org, an operator ann, a replay host
    sim, files under /etc/fleetlog. Real fleets get theirs from ``fleetlog deploy init``.
    """
    fleet = Fleet(
        name="example",
        root="fleet",
        shore=Machine("shore", ["shore.example.org"], zid="5a0e"),
        vehicles={"alpha": Machine("alpha", zid="a1fa"), "bravo": Machine("bravo", zid="b2a0")},
        operators=["ann"],
        replays=["sim"],
    )
    base = "/unused"
    return {
        "shore-router.json5": router_config(fleet, fleet.shore, base),
        "vehicle-router.json5": router_config(fleet, fleet.vehicles["alpha"], base),
        "vehicle-client.json5": client_config(
            fleet, "vehicles/alpha", "vehicle.pem", "vehicle.key", base
        ),
        "shore-client.json5": client_config(fleet, SHORE, "operator.pem", "operator.key", base),
        "operator-client.json5": client_config(
            fleet, "operators/ann", "operator.pem", "operator.key", base
        ),
    }
