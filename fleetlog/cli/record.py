"""``fleetlog record``: pLogger over Zenoh, one per vehicle."""

from __future__ import annotations

import dataclasses
import os
import signal
import socket
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Annotated, TypeAlias

import typer

from fleetlog.cli.app import app
from fleetlog.cli.options import (
    Config,
    Connect,
    Listen,
    Mode,
    NoScouting,
    Root,
    checked_root,
    checked_vehicle,
    session_options,
)
from fleetlog.cli.settings import settings
from fleetlog.errors import UsageError
from fleetlog.moos.mission import LoggerConfig, Mission, parse_mission
from fleetlog.query.server import LogServer
from fleetlog.recorder.engine import Recorder
from fleetlog.recorder.service import QUEUE, RecorderService, ServiceOptions
from fleetlog.storage.catalog import LogCatalog
from fleetlog.storage.columnar import limit_threads
from fleetlog.transport.notify import Notifier, Watchdog
from fleetlog.transport.queries import ZenohSession
from fleetlog.transport.session import SessionOptions, open_session, summarize

__all__ = ["load_config", "read_mission", "record"]

Attach: TypeAlias = "Callable[[ZenohSession, Recorder], Callable[[], None]]"


def read_mission(mission: Path) -> Mission:
    """Read and parse a mission file.

    Raises:
        UsageError: the file cannot be read or is binary.
        MissionError: the mission file is malformed (names the file and line).
    """
    try:
        text = mission.read_bytes().decode("utf-8", "surrogateescape")
    except FileNotFoundError:
        msg = f"mission file {mission} does not exist"
        raise UsageError(msg) from None
    except OSError as err:
        msg = f"cannot read mission file {mission}: {err.strerror}"
        raise UsageError(msg) from None
    if "\0" in text:
        msg = f"mission file {mission} is binary (it holds NUL bytes), not a MOOS mission file"
        raise UsageError(msg)
    return parse_mission(text, str(mission), env=os.environ)


def load_config(mission: Path | None, app_name: str) -> LoggerConfig:
    """Read the pLogger configuration from a mission file, or pLogger's defaults without one.

    Raises:
        UsageError: the mission file cannot be read.
        MissionError: the mission file is malformed (names the file and line).
    """
    if mission is None:
        return LoggerConfig.default(app_name)
    parsed = read_mission(mission)
    if parsed.block(app_name) is None:
        # pLogger then logs every variable (§6.4), which a misspelt --app-name or block hides.
        print(
            f"fleetlog: warning: {mission} has no 'ProcessConfig = {app_name}' block:"
            " logging every variable with pLogger's defaults",
            file=sys.stderr,
        )
    return parsed.logger_config(app_name)


def _default_vehicle() -> str:
    return socket.gethostname().split(".")[0] or "vehicle"


def _log_server(root: str, vehicle: str, cfg: LoggerConfig, zopts: SessionOptions) -> Attach:
    """Serve the recorder's log root to shore through the query services.

    Behind a router, the server has a Zenoh session of its own: its replies (1 MiB file
    ranges) must not share the recorder's link to the router. A router reads each link in
    order, and one that waits for a full radio to take a range holds up everything behind it
    on that link: the recorder's own posts and its answers to commands. A recorder that is a
    peer others connect to (``-l``) shares its session: nothing would route to a second one.
    """
    summary = summarize(zopts)
    own_session = bool(summary.connect) and not summary.listen

    def attach(recorder_session: ZenohSession, recorder: Recorder) -> Callable[[], None]:
        current = recorder.session
        log_root = current.dir_path.parent if current is not None else Path.cwd() / cfg.path

        def active() -> Path | None:
            live = recorder.session
            return live.dir_path if live is not None else None

        hint = Path(cfg.logging_directory_summary_file)
        catalog = LogCatalog(
            log_root,
            vehicle=vehicle,
            active=active,
            hint=hint if hint.is_absolute() else Path.cwd() / hint,
        )
        # The prune command checks acknowledged files against the digests the server
        # computed while sending them, and leaves the sessions it is sending alone.
        pruner = recorder.commands.pruner
        pruner.digest = lambda path: catalog.digests.sha256(
            catalog.root, (path.parent.name, path.name)
        )[0]
        pruner.fetching = lambda: catalog.leases.sessions(catalog.root.path)
        if not own_session:
            return LogServer(recorder_session, catalog, root=root, vehicle=vehicle).start().close
        session = open_session(zopts)
        try:
            server = LogServer(session, catalog, root=root, vehicle=vehicle).start()
        except BaseException:
            session.close()
            raise

        def close() -> None:
            try:
                server.close()
            finally:
                session.close()

        return close

    return attach


@app.command()
def record(
    mission: Annotated[
        Path | None,
        typer.Argument(
            metavar="MISSION",
            help="MOOS mission file with a 'ProcessConfig = pLogger' block"
            " [default: none, log every variable].",
            show_default=False,
        ),
    ] = None,
    vehicle: Annotated[
        str | None,
        typer.Option(
            "--vehicle",
            "-v",
            metavar="NAME",
            help="Vehicle to record [default: the mission's Community, else the host name].",
        ),
    ] = None,
    app_name: Annotated[
        str,
        typer.Option(
            "--app-name",
            metavar="NAME",
            help="The mission block to read, as pLogger's second argument.",
        ),
    ] = "pLogger",
    copy_dir: Annotated[
        list[Path] | None,
        typer.Option(
            "--copy-dir",
            metavar="DIR",
            help=(
                "Directory COPY_FILE_REQUEST may read from (repeatable; the mission's "
                "directory always may)."
            ),
        ),
    ] = None,
    queue: Annotated[
        int,
        typer.Option(
            "--queue",
            metavar="SAMPLES",
            min=512,
            help=(
                "Samples received but not yet written that the recorder may hold; a full"
                " queue makes Zenoh hold BLOCK publishers back. The default is about 0.15 s"
                " at 50k samples/s: what a crash can lose stays well under a second."
            ),
        ),
    ] = QUEUE,
    no_serve: Annotated[
        bool,
        typer.Option(
            "--no-serve", help="Do not serve the logs to shore (fleetlog fetch/query/sessions)."
        ),
    ] = False,
    root: Root = "fleet",
    mode: Mode = None,
    connect: Connect = None,
    listen: Listen = None,
    config: Config = None,
    no_multicast_scouting: NoScouting = False,
) -> None:
    """Record a vehicle's MOOS variables from Zenoh into MOOS log sessions, as pLogger does.

    Without a mission file it logs every variable of the vehicle into ./MOOSLog_<time>/ using
    an embedded Zenoh peer. Stop it with Ctrl-C (SIGINT) or SIGTERM: everything received is
    written and the files are closed. Behind a router (client mode) it records from its
    first second whether or not the router is up, and joins it when it answers.
    """
    # Greps and listings in this process parse logs with polars: one thread for them, so that
    # analysis never takes the cores the recorder's drain thread needs (before polars loads).
    limit_threads(1)
    key_root = checked_root(root)
    # A vehicle records whatever the network does: never wait for, nor give up on, a router.
    zopts = dataclasses.replace(
        session_options(mode, connect, listen, config, no_multicast_scouting), keep_trying=True
    )
    cfg = load_config(mission, app_name)
    if vehicle is not None:
        checked_vehicle(vehicle, "--vehicle")
    machine_vehicle = settings().get("vehicle")
    veh = vehicle or machine_vehicle or cfg.community or _default_vehicle()
    if vehicle is None and machine_vehicle and cfg.community and cfg.community != machine_vehicle:
        print(
            f"fleetlog: warning: recording as vehicle {machine_vehicle!r} (this machine's"
            f" settings), not as the mission's Community {cfg.community!r}; --vehicle chooses",
            file=sys.stderr,
        )
    mission_path = mission.resolve() if mission is not None else None
    dirs: list[Path] = []
    if mission_path is not None:
        dirs.append(mission_path.parent)
        dirs.extend(mission_path.parent / d for d in cfg.copy_file_dirs)
    dirs.extend(copy_dir or ())
    notifier = Notifier()
    watchdog = Watchdog(notifier)
    service = RecorderService(
        cfg,
        ServiceOptions(
            vehicle=veh,
            root=key_root,
            zenoh=zopts,
            mission_path=mission_path,
            copy_dirs=tuple(dirs),
            attach=None if no_serve else _log_server(key_root, veh, cfg, zopts),
            watchdog=watchdog.kick if watchdog.enabled else None,
            queue=queue,
        ),
    )

    def on_signal(signum: int, frame: object) -> None:
        notifier.stopping("closing every file")
        service.stop()
        # A second signal ends a shutdown that hangs, as users expect of a second Ctrl-C.
        signal.signal(signum, signal.SIG_DFL)

    signal.signal(signal.SIGINT, on_signal)
    signal.signal(signal.SIGTERM, on_signal)

    def ready(recorder: Recorder) -> None:
        current = recorder.session
        where = current.directory if current else "?"
        if current is not None and current.fallback:
            # pLogger announces its fallback; the MOOS_DEBUG post alone is easy to miss.
            print(
                f"fleetlog: warning: cannot create a session under {cfg.path}:"
                f" logging to the fallback {where} instead",
                file=sys.stderr,
            )
        for warning in current.warnings if current is not None else ():
            print(f"fleetlog: warning: {warning}", file=sys.stderr)
        print(
            f"fleetlog: recording vehicle {veh!r} into {where} (Ctrl-C to stop)",
            file=sys.stderr,
            flush=True,
        )
        notifier.ready(f"recording vehicle {veh} into {where}")

    try:
        view = service.run(on_ready=ready)
    finally:
        notifier.close()
    print(f"fleetlog: stopped: {view.summary()}", file=sys.stderr)
    for err in view.publish_errors[:3]:
        print(f"fleetlog: warning: {err}", file=sys.stderr)
