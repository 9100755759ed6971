"""``fleetlog replay``: uPlayBack over Zenoh, one vehicle or the whole fleet on one clock."""

from __future__ import annotations

import re
import signal
import sys
from contextlib import ExitStack
from pathlib import Path
from typing import Annotated

import typer
from rich.console import Console

from fleetlog.cli.app import app
from fleetlog.cli.options import (
    Config,
    Connect,
    Listen,
    Mode,
    NoScouting,
    Root,
    checked_root,
    checked_seconds,
    checked_vehicle,
    session_options,
)
from fleetlog.cli.replay_terminal import Keyboard, ProgressLine
from fleetlog.errors import UsageError
from fleetlog.replayer.control import MAX_RATE, MIN_RATE
from fleetlog.replayer.engine import Player
from fleetlog.replayer.filters import FilterSpec
from fleetlog.replayer.inputs import clock_warnings
from fleetlog.replayer.options import PlayOptions
from fleetlog.replayer.report import State
from fleetlog.replayer.schedule import DEFAULT_WINDOW
from fleetlog.replayer.service import ReplayConfig, ReplayService
from fleetlog.wire.keys import service_key

__all__ = ["parse_when", "replay"]

_CLOCK_RE = re.compile(r"(?:(\d+):)?(\d+):(\d+(?:\.\d*)?)")
_PANEL = "Playback"
_FILTER = "Filters"


def parse_when(text: str, option: str) -> tuple[float, bool]:
    """Read a ``--from``/``--to`` time: ``SECONDS``, ``[H:]MM:SS[.s]``, or ``@EPOCH``.

    Returns:
        ``(value, absolute)``: seconds from the replay's origin (the earliest LOGSTART, so
        the alog's own time column for one input), or an absolute epoch time.

    Raises:
        UsageError: the text is none of these.
    """
    raw = text.strip()
    absolute = raw.startswith("@")
    body = raw[1:] if absolute else raw
    match = _CLOCK_RE.fullmatch(body)
    try:
        if match is not None and not absolute:
            hours, minutes, seconds = match.groups()
            return int(hours or 0) * 3600 + int(minutes) * 60 + float(seconds), False
        value = float(body)
    except ValueError:
        value = float("nan")
    if value != value or value in (float("inf"), float("-inf")):  # NaN or infinite
        msg = (
            f"{option} {text!r}: give seconds from the start of the log (12.5), a clock time"
            " (1:02:03.5) or an absolute time (@1795345603.4)"
        )
        raise UsageError(msg)
    return value, absolute


@app.command()
def replay(
    inputs: Annotated[
        list[str],
        typer.Argument(
            metavar="INPUT",
            help="Alogs (.alog, .alog.gz, .alog.zst), session directories, or V:latest /"
            " V:SESSION.",
            show_default=False,
        ),
    ],
    rate: Annotated[
        float,
        typer.Option(
            "--rate",
            metavar="RATE",
            help=f"Playback rate, {MIN_RATE:g} ... {MAX_RATE:g}.",
            rich_help_panel=_PANEL,
        ),
    ] = 1.0,
    fast: Annotated[
        bool, typer.Option("--fast", help="As fast as possible.", rich_help_panel=_PANEL)
    ] = False,
    start: Annotated[
        str | None,
        typer.Option(
            "--from",
            metavar="T",
            help="Start at T: seconds from the log's start, [H:]MM:SS, or @EPOCH.",
            rich_help_panel=_PANEL,
        ),
    ] = None,
    stop: Annotated[
        str | None,
        typer.Option("--to", metavar="T", help="Stop at T (as --from).", rich_help_panel=_PANEL),
    ] = None,
    paused: Annotated[
        bool, typer.Option("--paused", help="Start paused.", rich_help_panel=_PANEL)
    ] = False,
    loop: Annotated[
        bool, typer.Option("--loop", help="Start again at the end.", rich_help_panel=_PANEL)
    ] = False,
    as_vehicle: Annotated[
        list[str] | None,
        typer.Option(
            "--as",
            metavar="V",
            help="Publish as vehicle V: once for every input, or once per input in order"
            " [default: the log's MOOS community].",
            rich_help_panel=_PANEL,
        ),
    ] = None,
    prefix: Annotated[
        str,
        typer.Option(
            "--prefix",
            metavar="P",
            help="Prepend P to every vehicle name (replay_ makes alpha replay_alpha), to keep"
            " replayed data apart from live vehicles (or use another --root).",
            rich_help_panel=_PANEL,
        ),
    ] = "",
    include_source: Annotated[
        list[str] | None,
        typer.Option(
            "--include-source",
            metavar="GLOB",
            help="Publish only these sources (the full source field or the bare process"
            " name; repeatable).",
            rich_help_panel=_FILTER,
        ),
    ] = None,
    exclude_source: Annotated[
        list[str] | None,
        typer.Option(
            "--exclude-source",
            metavar="GLOB",
            help="Do not publish these sources, e.g. the processes you run live (repeatable).",
            rich_help_panel=_FILTER,
        ),
    ] = None,
    var: Annotated[
        list[str] | None,
        typer.Option(
            "--var",
            metavar="GLOB",
            help="Publish only these variables (MOOS globs; repeatable).",
            rich_help_panel=_FILTER,
        ),
    ] = None,
    exclude_var: Annotated[
        list[str] | None,
        typer.Option(
            "--exclude-var",
            metavar="GLOB",
            help="Do not publish these variables (repeatable).",
            rich_help_panel=_FILTER,
        ),
    ] = None,
    no_keys: Annotated[
        bool,
        typer.Option(
            "--no-keys", help="Do not read keys from the terminal.", rich_help_panel=_PANEL
        ),
    ] = False,
    seek_step: Annotated[
        float,
        typer.Option(
            "--seek-step",
            metavar="SECONDS",
            help="Seconds an arrow key seeks.",
            rich_help_panel=_PANEL,
        ),
    ] = 5.0,
    keep_duplicates: Annotated[
        bool,
        typer.Option(
            "--keep-duplicates",
            help="Also play re-delivered duplicate lines, as uPlayBack does.",
            rich_help_panel=_PANEL,
        ),
    ] = False,
    sort_window: Annotated[
        int,
        typer.Option(
            "--sort-window",
            metavar="N",
            help="Entries per input held back to put out-of-order lines in time order.",
            rich_help_panel=_PANEL,
        ),
    ] = DEFAULT_WINDOW,
    no_db_time: Annotated[
        bool,
        typer.Option("--no-db-time", help="Do not post PLAYBACK_DB_TIME.", rich_help_panel=_PANEL),
    ] = False,
    skip_bad_lines: Annotated[
        bool,
        typer.Option(
            "--skip-bad-lines",
            help="Skip malformed lines (and count them) instead of stopping.",
            rich_help_panel=_PANEL,
        ),
    ] = False,
    cache_dir: Annotated[
        Path | None,
        typer.Option(
            "--cache-dir",
            metavar="DIR",
            help="Where remote inputs (V:latest, V:SESSION) are fetched to"
            " [default: ~/.cache/fleetlog/replay].",
            rich_help_panel=_PANEL,
        ),
    ] = None,
    wait: Annotated[
        float,
        typer.Option(
            "--wait",
            metavar="SECONDS",
            help="Wait this long for each vehicle's subscribers before playing.",
            rich_help_panel=_PANEL,
        ),
    ] = 1.0,
    into_live: Annotated[
        bool,
        typer.Option(
            "--into-live",
            help="Publish into the keys of a vehicle whose recorder is running now (its live"
            " log gets the replayed entries). Without it such a replay is refused.",
            rich_help_panel=_PANEL,
        ),
    ] = False,
    root: Root = "fleet",
    mode: Mode = None,
    connect: Connect = None,
    listen: Listen = None,
    config: Config = None,
    no_multicast_scouting: NoScouting = False,
) -> None:
    """Replay alogs into Zenoh as though the original processes were running.

    An INPUT is an alog, a session directory, or a vehicle's session fetched through its
    query service first: V:latest or V:SESSION. Each entry is published on
    <root>/V/var/VAR with its original source, type and exact value, at its recorded time
    (scaled by --rate). Inputs from several vehicles play together on one clock by absolute
    time, each under its own vehicle. In a terminal: space pauses, arrows seek, +/- change
    the rate, n steps one entry, q quits. Remotely: query
    <root>/V/@fleetlog/replay/control?cmd=pause|resume|seek;t=S|rate;x=R|step|stop, and
    follow <root>/V/@fleetlog/replay/status (or use fleetlog replay-ctl).

    A replay into a vehicle that is live now (its recorder runs) is refused: use --prefix
    or another --root to replay beside it, or --into-live to replay into it.
    """
    key_root = checked_root(root)
    zopts = session_options(mode, connect, listen, config, no_multicast_scouting)
    checked_seconds(wait, "--wait")
    checked_seconds(seek_step, "--seek-step", zero=False)
    for name in as_vehicle or ():
        checked_vehicle(name, "--as")
    when_from = parse_when(start, "--from") if start is not None else None
    when_to = parse_when(stop, "--to") if stop is not None else None
    filters = FilterSpec(
        tuple(include_source or ()),
        tuple(exclude_source or ()),
        tuple(var or ()),
        tuple(exclude_var or ()),
    )
    console = Console(stderr=True, highlight=False, soft_wrap=True)
    service = ReplayService(
        ReplayConfig(
            inputs=inputs,
            vehicles=tuple(as_vehicle or ()),
            root=key_root,
            zenoh=zopts,
            wait=wait,
            errors="skip" if skip_bad_lines else "raise",
            cache=cache_dir,
            announce=lambda text: console.print(f"fleetlog: {text}", markup=False),
            into_live=into_live,
        )
    )
    service.open_inputs()
    origin = service.origin

    def relative(when: tuple[float, bool] | None) -> float | None:
        if when is None:
            return None
        value, absolute = when
        return value - origin if absolute else value

    player = service.open(
        PlayOptions(
            rate=None if fast else rate,
            start=relative(when_from),
            stop=relative(when_to),
            paused=paused,
            loop=loop,
            filters=filters,
            prefix=prefix,
            window=sort_window,
            dedupe=not keep_duplicates,
            db_time=not no_db_time,
        )
    )
    keys = not no_keys and sys.stdin.isatty()
    window = start is not None or stop is not None
    _run(service, player, console, key_root, keys=keys, seek_step=seek_step, window=window)


def _run(
    service: ReplayService,
    player: Player,
    console: Console,
    root: str,
    *,
    keys: bool,
    seek_step: float,
    window: bool = False,
) -> None:
    vehicles = ", ".join(dict.fromkeys(player.vehicles))
    control = service_key(root, player.vehicles[0], "replay", "control")
    console.print(
        f"fleetlog: replaying {len(service.inputs)} input(s) as {vehicles}; control: {control}",
        markup=False,
    )
    for warning in clock_warnings(service.inputs):
        console.print(f"fleetlog: warning: {warning}", markup=False)

    stopping: list[int] = []

    def on_signal(signum: int, frame: object) -> None:
        if stopping:
            raise KeyboardInterrupt  # a second Ctrl-C: do not wait for the end of the replay
        stopping.append(signum)
        player.stop()

    signal.signal(signal.SIGINT, on_signal)
    signal.signal(signal.SIGTERM, on_signal)
    live = console.is_terminal

    def ready(player: Player) -> None:
        if service.missing:
            names = ", ".join(service.missing)
            console.print(f"fleetlog: note: nothing subscribes to {names} yet", markup=False)

    with ExitStack() as terminal:
        if keys:
            terminal.enter_context(Keyboard(player.submit, seek_step))
        if live:
            progress = terminal.enter_context(ProgressLine(player.status, console, keys=keys))
            player.idle_hooks.append(progress.refresh)
        summary = service.run(on_ready=ready)
    for line in summary.lines():
        console.print(f"fleetlog: {line}" if not line.startswith(" ") else line, markup=False)
    if window and summary.state is State.FINISHED and not summary.published + summary.filtered:
        # Else a --from past the end (or a --to before the start) looks like an empty log.
        console.print(
            "fleetlog: note: no entry lies between --from and --to; nothing was played",
            markup=False,
        )
    if service.unconfirmed and any(c.published for c in summary.vehicles.values()):
        names = ", ".join(service.unconfirmed)
        console.print(f"fleetlog: note: no recorder confirmed receipt for {names}", markup=False)
