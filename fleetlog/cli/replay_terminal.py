"""The replay's terminal: keys in (raw mode), a progress line and the summary out (rich).

Both are used only when the terminal is there: keys when stdin is a TTY (and ``--no-keys``
is not given), the live progress line when stderr is a TTY. The progress line is redrawn
by the player itself, from its idle time (:attr:`fleetlog.replayer.engine.Player.idle_hooks`),
never by a thread of rich's own: a redraw holds the GIL for 0.3 ms, and up to 5 ms on a busy
machine, which would make the entry due meanwhile late by as much.
"""

from __future__ import annotations

import os
import select
import sys
import termios
import threading
import tty
from collections.abc import Callable
from types import TracebackType
from typing import Any

from rich.console import Console
from rich.live import Live
from rich.text import Text

from fleetlog.replayer.control import Command, KeyDecoder
from fleetlog.replayer.report import State, Status

__all__ = ["HELP", "Keyboard", "ProgressLine", "format_status"]

HELP = "space pause · ←/→ seek · ↑/↓ seek more · +/- rate · n step · q quit"
_ICONS = {
    State.PLAYING: "▶",
    State.PAUSED: "⏸",
    State.WAITING: "⧗",
    State.FINISHED: "■",
    State.STOPPED: "■",
}


def _clock(seconds: float) -> str:
    sign = "-" if seconds < 0 else ""
    seconds = abs(seconds)
    hours, rest = divmod(seconds, 3600)
    minutes, secs = divmod(rest, 60)
    if hours:
        return f"{sign}{int(hours)}:{int(minutes):02d}:{secs:06.3f}"
    return f"{sign}{int(minutes)}:{secs:06.3f}"


def format_status(status: Status, width: int = 20) -> str:
    """Return a one-line rendering of the status (position, bar, %, rate, counts)."""
    rate = "fast" if status.rate is None else f"×{status.rate:g}"
    fraction = status.fraction
    if fraction is None:
        where = f"{_clock(status.offset)}"
        bar = ""
    else:
        assert status.end is not None
        filled = round(fraction * width)
        bar = " [" + "#" * filled + "." * (width - filled) + f"] {fraction * 100:5.1f}%"
        where = f"{_clock(status.offset)} / {_clock(status.end)}"
    state = f"{_ICONS[status.state]} {status.state.value}"
    counts = f"published {status.published}"
    if status.filtered:
        counts += f", filtered {status.filtered}"
    return f"{state}  {where}{bar}  {rate}  {counts}"


class ProgressLine:
    """A live status line on stderr, redrawn from the player's status.

    Args:
        status: returns the current status.
        console: where to draw (stderr by default).
        keys: show the key help under the line.
    """

    def __init__(
        self, status: Callable[[], Status], console: Console | None = None, *, keys: bool = False
    ) -> None:
        self._status = status
        self.console = console or Console(stderr=True)
        self._keys = keys
        self._live: Live | None = None

    def _render(self) -> Text:
        text = Text(format_status(self._status()), no_wrap=True, overflow="ellipsis")
        if self._keys:
            text.append("\n" + HELP, style="dim")
        return text

    def __enter__(self) -> ProgressLine:
        self._live = Live(
            get_renderable=self._render,
            console=self.console,
            auto_refresh=False,
            transient=True,
            redirect_stdout=False,
            redirect_stderr=False,
        )
        self._live.start()
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        if self._live is not None:
            self._live.stop()
            self._live = None

    def refresh(self) -> None:
        """Redraw the line (call it from the player's idle hooks)."""
        if self._live is not None:
            self._live.refresh()


class Keyboard:
    """Reads keys from a terminal stdin in a thread and submits the commands they mean.

    The terminal is put in cbreak mode (keys arrive one by one, unechoed, Ctrl-C still
    interrupts) and restored on exit.

    Args:
        submit: called with each command.
        seek_step: seconds an arrow key seeks.
        fd: the terminal's file descriptor (stdin by default).
    """

    def __init__(
        self, submit: Callable[[Command], Any], seek_step: float = 5.0, fd: int | None = None
    ) -> None:
        self._submit = submit
        self._decoder = KeyDecoder(seek_step)
        self._fd = sys.stdin.fileno() if fd is None else fd
        self._saved: list[Any] | None = None
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="fleetlog-keys", daemon=True)

    def __enter__(self) -> Keyboard:
        self._saved = termios.tcgetattr(self._fd)
        tty.setcbreak(self._fd)
        self._thread.start()
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self._stop.set()
        self._thread.join(1.0)
        if self._saved is not None:
            termios.tcsetattr(self._fd, termios.TCSADRAIN, self._saved)
            self._saved = None

    def _run(self) -> None:
        while not self._stop.is_set():
            ready, _, _ = select.select([self._fd], [], [], 0.1)
            if not ready:
                continue
            try:
                data = os.read(self._fd, 64)
            except OSError:
                return
            if not data:
                return
            for command in self._decoder.feed(data):
                self._submit(command)
