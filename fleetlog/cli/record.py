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
from fleetlog.cli.record_options import (
    KeepSessionsOption,
    MaxLogSizeOption,
    MinFreeDiskOption,
    SnapshotAfterOption,
    SnapshotMemoryOption,
    SnapshotSecondsOption,
    SnapshotTriggerOption,
)
from fleetlog.cli.settings import settings
from fleetlog.errors import FormatError, MissionError, UsageError
from fleetlog.moos.keep_settings import with_disk_options, with_snapshot_options
from fleetlog.moos.mission import LoggerConfig, Mission, parse_mission
from fleetlog.moos.param_check import check_logger_block
from fleetlog.moos.recording_modes import (
    MAX_NOTES,
    MAX_TAGS,
    MIN_SPLIT_DURATION,
    MIN_SPLIT_SIZE,
    RecordingModes,
    check_tag,
    parse_note,
)
from fleetlog.moos.units import parse_duration, parse_size
from fleetlog.query.server import LogServer
from fleetlog.recorder.engine import Recorder
from fleetlog.recorder.service import QUEUE, RecorderService, ServiceOptions
from fleetlog.storage.catalog import LogCatalog
from fleetlog.storage.columnar import limit_threads
from fleetlog.storage.heap import HeapKeeper
from fleetlog.transport.notify import Notifier, Watchdog
from fleetlog.transport.queries import ZenohSession
from fleetlog.transport.session import (
    SessionOptions,
    open_session,
    prefer_runtime,
    summarize,
)

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


def load_config(mission: Path | None, app_name: str, *, strict: bool = False) -> LoggerConfig:
    """Read the pLogger configuration from a mission file, or pLogger's defaults without one.

    What pLogger would read silently wrong (an unknown parameter, a ``Log =`` period that is
    not a number) is printed as a warning, or refused with ``strict``.

    Raises:
        UsageError: the mission file cannot be read.
        MissionError: the mission file is malformed (names the file and line), or with
            ``strict``, holds a line pLogger would read silently wrong.
    """
    if mission is None:
        return LoggerConfig.default(app_name)
    parsed = read_mission(mission)
    warnings = check_logger_block(parsed.block(app_name), parsed.path)
    if warnings and strict:
        first = warnings[0]
        more = f" (and {len(warnings) - 1} more)" if len(warnings) > 1 else ""
        msg = f"{first.reason}{more}; --strict refuses it"
        raise MissionError(msg, first.path, first.lineno)
    for warning in warnings:
        print(f"fleetlog: warning: {warning}", file=sys.stderr)
    if parsed.block(app_name) is None:
        # pLogger then logs every variable (§6.4), which a misspelt --app-name or block hides.
        print(
            f"fleetlog: warning: {mission} has no 'ProcessConfig = {app_name}' block:"
            " logging every variable with pLogger's defaults",
            file=sys.stderr,
        )
    return parsed.logger_config(app_name)


def recording_modes(
    base: RecordingModes,
    *,
    split_size: str | None,
    split_duration: str | None,
    paused: bool,
    notes: list[str],
    tags: list[str],
    file_timestamp: bool,
) -> RecordingModes:
    """Return the mission's recording modes with the command line's options over them.

    A ``--note`` replaces the mission's note of the same key; ``--tag`` adds to its tags.

    Raises:
        UsageError: an option's value cannot be used (the message names the option).
    """
    size, duration = base.split_size, base.split_duration
    try:
        if split_size is not None:
            size = parse_size(split_size, name="--split-size") or None
            if size is not None and size < MIN_SPLIT_SIZE:
                msg = f"--split-size {split_size!r} is below the smallest part, 1MB"
                raise UsageError(msg)
        if split_duration is not None:
            duration = parse_duration(split_duration, name="--split-duration") or None
            if duration is not None and duration < MIN_SPLIT_DURATION:
                msg = f"--split-duration {split_duration!r} is below the shortest part, 1s"
                raise UsageError(msg)
        merged = dict(base.notes)
        for text in notes:
            key, value = parse_note(text)
            merged.pop(key, None)
            merged[key] = value
    except FormatError as err:
        raise UsageError(str(err)) from None
    all_tags = list(base.tags)
    for tag in (t.strip() for text in tags for t in text.split(",")):
        why = check_tag(tag)
        if why is not None:
            msg = f"--tag {tag[:80]!r}: {why}"
            raise UsageError(msg)
        if tag not in all_tags:
            all_tags.append(tag)
    if len(merged) > MAX_NOTES or len(all_tags) > MAX_TAGS:
        msg = f"at most {MAX_NOTES} notes and {MAX_TAGS} tags"
        raise UsageError(msg)
    if (size or duration) and not file_timestamp:
        msg = "splitting needs time-stamped session names (the mission sets FileTimeStamp = false)"
        raise UsageError(msg)
    return RecordingModes(
        split_size=size,
        split_duration=duration,
        start_paused=paused or base.start_paused,
        notes=tuple(merged.items()),
        tags=tuple(all_tags),
    )


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
        # The warmer hashes each session the recorder closes: told, it needs no polling.
        changes = recorder.session_changes
        if not own_session:
            server = LogServer(
                recorder_session, catalog, root=root, vehicle=vehicle, session_changes=changes
            )
            return server.start().close
        session = open_session(zopts)
        try:
            server = LogServer(
                session, catalog, root=root, vehicle=vehicle, session_changes=changes
            ).start()
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
    split_size: Annotated[
        str | None,
        typer.Option(
            "--split-size",
            metavar="SIZE",
            help="Start the next part of the session when its files hold SIZE on disk"
            " (500MB, 2GiB; at least 1MB; 0: never) [default: the mission's SplitSize].",
            show_default=False,
        ),
    ] = None,
    split_duration: Annotated[
        str | None,
        typer.Option(
            "--split-duration",
            metavar="TIME",
            help="Start the next part of the session after TIME (600, 10min, 1h; at least"
            " 1s; 0: never) [default: the mission's SplitDuration].",
            show_default=False,
        ),
    ] = None,
    paused: Annotated[
        bool,
        typer.Option(
            "--paused",
            help="Start paused: open the session, write nothing until a RESUME (PLOGGER_CMD"
            " or fleetlog recorder-ctl resume).",
        ),
    ] = False,
    note: Annotated[
        list[str] | None,
        typer.Option(
            "--note",
            metavar="KEY:VALUE",
            help="A note on every session (repeatable; over the mission's Note of that key).",
        ),
    ] = None,
    tag: Annotated[
        list[str] | None,
        typer.Option("--tag", metavar="TAG", help="A tag on every session (repeatable, or a, b)."),
    ] = None,
    strict: Annotated[
        bool,
        typer.Option(
            "--strict",
            help="Refuse a mission whose pLogger block has a parameter no one knows or a"
            " Log period that is not a number (warnings otherwise).",
        ),
    ] = False,
    no_serve: Annotated[
        bool,
        typer.Option(
            "--no-serve", help="Do not serve the logs to shore (fleetlog fetch/query/sessions)."
        ),
    ] = False,
    snapshot_seconds: SnapshotSecondsOption = None,
    snapshot_memory: SnapshotMemoryOption = None,
    snapshot_after: SnapshotAfterOption = None,
    snapshot_trigger: SnapshotTriggerOption = None,
    min_free_disk: MinFreeDiskOption = None,
    keep_sessions: KeepSessionsOption = None,
    max_log_size: MaxLogSizeOption = None,
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
    # Zenoh's receiving threads watch the links themselves: no thread switch per message
    # (before the first session; an operator's ZENOH_RUNTIME wins).
    prefer_runtime()
    key_root = checked_root(root)
    # A vehicle records whatever the network does: never wait for, nor give up on, a router.
    zopts = dataclasses.replace(
        session_options(mode, connect, listen, config, no_multicast_scouting), keep_trying=True
    )
    cfg = load_config(mission, app_name, strict=strict)
    cfg = dataclasses.replace(
        cfg,
        modes=recording_modes(
            cfg.modes,
            split_size=split_size,
            split_duration=split_duration,
            paused=paused,
            notes=note or [],
            tags=tag or [],
            file_timestamp=cfg.file_timestamp,
        ),
    )
    try:
        cfg = dataclasses.replace(
            cfg,
            snapshot=with_snapshot_options(
                cfg.snapshot,
                seconds=snapshot_seconds,
                memory=snapshot_memory,
                after=snapshot_after,
                triggers=snapshot_trigger or (),
            ),
            disk=with_disk_options(
                cfg.disk,
                min_free=min_free_disk,
                keep_sessions=keep_sessions,
                max_log_size=max_log_size,
            ),
        )
    except FormatError as bad:
        raise UsageError(str(bad)) from None
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
            watchdog_every=(watchdog.interval or 3.0) / 3,
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
        if cfg.snapshot is not None:
            held = f"the last {cfg.snapshot.seconds:g} s"
            print(
                f"fleetlog: snapshot mode for vehicle {veh!r}: holding {held} in memory,"
                " writing a session at each SNAPSHOT (Ctrl-C to stop)",
                file=sys.stderr,
                flush=True,
            )
            notifier.ready(f"snapshot mode for vehicle {veh}")
            return
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
        if cfg.modes.start_paused:
            print("fleetlog: paused: nothing is written until a RESUME", file=sys.stderr)
        print(
            f"fleetlog: recording vehicle {veh!r} into {where} (Ctrl-C to stop)",
            file=sys.stderr,
            flush=True,
        )
        notifier.ready(f"recording vehicle {veh} into {where}")

    try:
        # the C heap's bursts (Zenoh's buffers, file ranges) must not ratchet up the RSS
        with HeapKeeper():
            view = service.run(on_ready=ready)
    finally:
        notifier.close()
    print(f"fleetlog: stopped: {view.summary()}", file=sys.stderr)
    for err in view.publish_errors[:3]:
        print(f"fleetlog: warning: {err}", file=sys.stderr)
