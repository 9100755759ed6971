"""The bridge's configuration from a mission file, as every MOOS app reads its own.

File scope: ``ServerHost`` (default ``localhost``), ``ServerPort`` (default 9000) and
``Community`` (the MOOSDB's default is ``#1``). The block ``ProcessConfig = fleetlog_bridge``
may name which variables cross, with MOOS globs (``*`` any run, ``?`` one character),
comma-separated, and may repeat:

* ``ToZenoh = NAV_*, DEPLOY`` — MOOS → Zenoh, by MOOS wildcard registration (default ``*``:
  every variable, the MOOSDB's own ``DB_*`` included). With explicit patterns ``DB_*`` is
  added, so a recording still names its vehicle in the MOOS-IvP tools.
* ``FromZenoh = NAV_*`` — Zenoh → MOOS (default ``*``); ``FromZenoh = none`` posts nothing
  into the MOOSDB.
"""

from __future__ import annotations

from dataclasses import dataclass

from fleetlog.errors import MissionError
from fleetlog.moos.mission import Mission

__all__ = ["BRIDGE_APP", "DEFAULT_COMMUNITY", "DEFAULT_PORT", "BridgeConfig", "bridge_config"]

#: the bridge's MOOS name and the name of its mission block
BRIDGE_APP = "fleetlog_bridge"
#: the MOOSDB's port and community when the mission names none
DEFAULT_PORT = 9000
DEFAULT_COMMUNITY = "#1"
DEFAULT_HOST = "localhost"


@dataclass(frozen=True)
class BridgeConfig:
    """Where the MOOSDB is and what crosses the bridge.

    Attributes:
        host: the MOOSDB's host (``ServerHost``).
        port: the MOOSDB's port (``ServerPort``).
        community: the community (``Community``), or None when the mission names none (the
            MOOSDB's welcome then says it).
        to_zenoh: MOOS globs of the variables forwarded to Zenoh.
        from_zenoh: MOOS globs of the variables posted into the MOOSDB (empty: none).
    """

    host: str = DEFAULT_HOST
    port: int = DEFAULT_PORT
    community: str | None = None
    to_zenoh: tuple[str, ...] = ("*",)
    from_zenoh: tuple[str, ...] = ("*",)


def _patterns(mission: Mission, app: str, name: str) -> tuple[str, ...] | None:
    block = mission.block(app)
    if block is None:
        return None
    found: list[str] = []
    seen = False
    for param in block.raw_values(name):
        seen = True
        for item in param.value.split(","):
            if not item:
                continue
            if "=" in item:
                msg = f"{param.name} pattern {item!r} holds '=', which MOOS cannot register"
                raise MissionError(msg, mission.path, param.lineno)
            found.append(item)
    return tuple(dict.fromkeys(found)) if seen else None


def _port(mission: Mission) -> int:
    param = mission.global_param("ServerPort")
    if param is None or not param.value:
        return DEFAULT_PORT
    text = param.value
    if not text.isdigit() or not 0 < int(text) < 65536:
        msg = f"{param.name} value {text!r} is not a TCP port (1-65535)"
        raise MissionError(msg, mission.path, param.lineno)
    return int(text)


def bridge_config(mission: Mission | None, app: str = BRIDGE_APP) -> BridgeConfig:
    """Read the bridge's configuration; the defaults without a mission.

    Raises:
        MissionError: ``ServerPort`` is not a port, or a pattern cannot be registered.
    """
    if mission is None:
        return BridgeConfig()
    to_zenoh = _patterns(mission, app, "ToZenoh") or ("*",)
    if "*" not in to_zenoh and "DB_*" not in to_zenoh:
        to_zenoh = (*to_zenoh, "DB_*")
    from_zenoh = _patterns(mission, app, "FromZenoh")
    if from_zenoh is None:
        from_zenoh = ("*",)
    elif tuple(p.lower() for p in from_zenoh) == ("none",):
        from_zenoh = ()
    return BridgeConfig(
        host=mission.global_value("ServerHost") or DEFAULT_HOST,
        port=_port(mission),
        community=mission.community,
        to_zenoh=to_zenoh,
        from_zenoh=from_zenoh,
    )
