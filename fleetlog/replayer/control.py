r"""Commands that steer a replay, and the two ways they arrive: keys and remote queries.

The player takes :data:`Command` values from any thread. A terminal sends them through
:class:`KeyDecoder` (space pauses and resumes, the arrows seek, ``+``/``-`` change the rate,
``n`` steps one entry), a UI or ``fleetlog replay-ctl`` through the Zenoh control queryable,
which speaks fleetlog's one control schema (docs/wire.md, "Control"): a JSON request
``{"cmd": "seek", "t": 120}`` in the query's payload, or the same as selector parameters,
read by :func:`parse_request`::

    <root>/<V>/@fleetlog/replay/control?cmd=pause
    ...?cmd=resume | cmd=toggle | cmd=stop | cmd=status
    ...?cmd=seek;t=120        (seconds from the replay's origin, as the display shows)
    ...?cmd=seek;dt=-5        (relative)
    ...?cmd=rate;x=2          (0.1 ... 100, or x=fast; x=+ and x=- move along the ladder)
    ...?cmd=step              (the next entry; n=N entries, or dt=S seconds of log time)

The reply is ``{"ok", "cmd", "did", "why"}`` with the status after the command beside them
(``state``, ``position``, ``rate``, ...; :func:`describe` words ``did``).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

from fleetlog.errors import FormatError, ReplayError
from fleetlog.wire.control import parse_control_request

__all__ = [
    "MAX_RATE",
    "MIN_RATE",
    "RATES",
    "REPLAY_COMMANDS",
    "Command",
    "KeyDecoder",
    "Pause",
    "Resume",
    "Seek",
    "SetRate",
    "Step",
    "Stop",
    "Toggle",
    "check_rate",
    "describe",
    "next_rate",
    "parse_query",
    "parse_request",
]

MIN_RATE = 0.1
MAX_RATE = 100.0
#: The rates ``+`` and ``-`` move between; past the top is "as fast as possible".
RATES = (0.1, 0.2, 0.5, 1.0, 2.0, 5.0, 10.0, 20.0, 50.0, 100.0)
#: The replay's control commands and the arguments each may take (all optional).
REPLAY_COMMANDS: Mapping[str, tuple[str, ...]] = {
    "pause": (),
    "resume": (),
    "play": (),
    "toggle": (),
    "stop": (),
    "seek": ("t", "dt"),
    "rate": ("x",),
    "step": ("n", "dt"),
    "status": (),
}
#: Arguments a JSON request may give as numbers.
_NUMBERS = frozenset({"t", "dt", "x", "n"})


@dataclass(frozen=True, slots=True)
class Pause:
    """Stop advancing; the position stays where it is."""


@dataclass(frozen=True, slots=True)
class Resume:
    """Play on from the position."""


@dataclass(frozen=True, slots=True)
class Toggle:
    """Pause if playing, resume if paused."""


@dataclass(frozen=True, slots=True)
class Stop:
    """End the replay (the summary is still given)."""


@dataclass(frozen=True, slots=True)
class Seek:
    """Jump without publishing what lies between.

    Attributes:
        to: the new position, seconds from the replay's origin; or None with ``by``.
        by: seconds to move from the current position (negative: back).
    """

    to: float | None = None
    by: float | None = None


@dataclass(frozen=True, slots=True)
class SetRate:
    """Change the rate.

    Attributes:
        rate: the new rate (0.1 ... 100), None for as fast as possible.
        steps: instead of ``rate``, move this many places along :data:`RATES`.
    """

    rate: float | None = 1.0
    steps: int = 0


@dataclass(frozen=True, slots=True)
class Step:
    """Publish the next entries at once, then stay paused.

    Attributes:
        entries: how many entries (when ``seconds`` is None).
        seconds: instead, every entry in the next this many seconds of log time.
    """

    entries: int = 1
    seconds: float | None = None


Command = Pause | Resume | Toggle | Stop | Seek | SetRate | Step


def check_rate(rate: float) -> float:
    """Return ``rate`` if it is within 0.1 ... 100.

    Raises:
        ReplayError: it is not.
    """
    if not (MIN_RATE <= rate <= MAX_RATE) or math.isnan(rate):
        msg = f"rate {rate:g} is outside {MIN_RATE:g} ... {MAX_RATE:g} (use --fast for no pacing)"
        raise ReplayError(msg)
    return rate


def next_rate(rate: float | None, steps: int) -> float | None:
    """Move ``steps`` places along :data:`RATES` from ``rate`` (None: as fast as possible).

    From a rate between two ladder rates, one step up goes to the next one above it.
    Past 100 is as fast as possible; below 0.1 stays 0.1.
    """
    ladder = [*RATES, None]
    if rate is None:
        place = len(ladder) - 1
    elif steps > 0:
        place = max(i for i, r in enumerate(RATES) if r <= rate + 1e-9)
    else:
        place = min(i for i, r in enumerate(RATES) if r >= rate - 1e-9)
    place = min(max(place + steps, 0), len(ladder) - 1)
    return ladder[place]


def _number(params: Mapping[str, str], name: str, cmd: str) -> float | None:
    text = params.get(name)
    if text is None or text == "":
        return None
    try:
        value = float(text)
    except ValueError:
        msg = f"cmd={cmd}: {name}={text!r} is not a number"
        raise ReplayError(msg) from None
    if not math.isfinite(value):
        msg = f"cmd={cmd}: {name}={text!r} is not a finite number"
        raise ReplayError(msg)
    return value


def _rate(params: Mapping[str, str]) -> SetRate:
    text = params.get("x", "").strip()
    if text in ("fast", "max", "inf"):
        return SetRate(None)
    if text in ("+", "faster", "up"):
        return SetRate(steps=1)
    if text in ("-", "slower", "down"):
        return SetRate(steps=-1)
    value = _number(params, "x", "rate")
    if value is None:
        msg = "cmd=rate needs x=RATE (0.1 ... 100), x=fast, x=+ or x=-"
        raise ReplayError(msg)
    return SetRate(check_rate(value))


def parse_query(params: Mapping[str, str]) -> Command:
    """Read a control query's parameters (see the module docstring).

    Raises:
        ReplayError: an unknown command or a missing or malformed parameter.
    """
    cmd = params.get("cmd", "").strip().lower()
    simple: dict[str, Command] = {
        "pause": Pause(),
        "resume": Resume(),
        "play": Resume(),
        "toggle": Toggle(),
        "stop": Stop(),
    }
    if cmd in simple:
        return simple[cmd]
    if cmd == "seek":
        to = _number(params, "t", cmd)
        by = _number(params, "dt", cmd)
        if (to is None) == (by is None):
            msg = "cmd=seek needs exactly one of t=SECONDS (from the origin) or dt=SECONDS"
            raise ReplayError(msg)
        return Seek(to, by)
    if cmd == "rate":
        return _rate(params)
    if cmd == "step":
        seconds = _number(params, "dt", cmd)
        count = _number(params, "n", cmd)
        if seconds is not None:
            if seconds <= 0:
                msg = "cmd=step: dt must be more than 0 seconds"
                raise ReplayError(msg)
            return Step(seconds=seconds)
        if count is not None and (count < 1 or count != int(count)):
            msg = "cmd=step: n must be a whole number of entries, 1 or more"
            raise ReplayError(msg)
        return Step(1 if count is None else int(count))
    known = "pause, resume, toggle, seek, rate, step, stop"
    msg = f"unknown replay command cmd={cmd!r}; known: {known}" if cmd else f"give cmd=: {known}"
    raise ReplayError(msg)


def parse_request(payload: bytes | None, parameters: str) -> tuple[str, Command | None]:
    """Read a control request: a JSON payload, or selector parameters (``;`` or ``&``).

    Returns:
        The command's name and the command (None for ``status``, which changes nothing).

    Raises:
        FormatError: the request is malformed (not JSON, too large, an unknown command or
            argument, a value that is not a number where one is needed...).
    """
    request = parse_control_request(
        payload,
        parameters.replace("&", ";"),
        commands=REPLAY_COMMANDS,
        optional=True,
        numbers=_NUMBERS,
    )
    if request.cmd == "status":
        return request.cmd, None
    try:
        return request.cmd, parse_query({"cmd": request.cmd, **request.args})
    except ReplayError as err:
        raise FormatError(str(err)) from None


def _clock(seconds: float) -> str:
    minutes, rest = divmod(max(seconds, 0.0), 60.0)
    return f"{int(minutes)}:{rest:04.1f}"


def describe(cmd: str, status: Mapping[str, object]) -> str:
    """Say in one sentence where the replay is after ``cmd`` (a reply's ``did``)."""
    offset = status.get("offset")
    where = _clock(offset) if isinstance(offset, int | float) else "?"
    end = status.get("end")
    if isinstance(end, int | float):
        where += f" of {_clock(end)}"
    rate = status.get("rate")
    pace = "as fast as possible" if rate == "fast" else f"at {rate}x"
    state = status.get("state")
    sentences = {
        "pause": f"{state} at {where}",
        "resume": f"{state} from {where} {pace}",
        "play": f"{state} from {where} {pace}",
        "toggle": f"{state} at {where}",
        "stop": f"{state} at {where}",
        "seek": f"moved to {where} ({state})",
        "rate": f"{state} {pace} at {where}",
        "step": f"stepped to {where} ({state})",
    }
    return sentences.get(cmd, f"{state} at {where} {pace}")


class KeyDecoder:
    r"""Turns terminal key presses (bytes from a raw-mode stdin) into commands.

    Space or ``p`` toggles pause; ``→``/``←`` seek by ``seek_step`` seconds, ``↑``/``↓`` by
    ten times that; ``+`` (or ``=``) and ``-`` move the rate along :data:`RATES`; ``n`` steps
    one entry, ``N`` one second; ``q`` stops. Escape sequences split across reads are kept
    until they are whole.

    Args:
        seek_step: seconds an arrow key seeks.
    """

    def __init__(self, seek_step: float = 5.0) -> None:
        self.seek_step = seek_step
        self._pending = b""

    def feed(self, data: bytes) -> list[Command]:
        """Return the commands the bytes complete."""
        buf = self._pending + data
        self._pending = b""
        out: list[Command] = []
        i = 0
        while i < len(buf):
            if buf[i] == 0x1B:  # ESC: an arrow is ESC [ A..D (or ESC O A..D)
                seq = buf[i : i + 3]
                if len(seq) < 3 and seq in (b"\x1b", b"\x1b[", b"\x1bO"):
                    self._pending = seq
                    break
                arrow = self._arrow(seq)
                if arrow is not None:
                    out.append(arrow)
                    i += 3
                else:
                    i += 1
                continue
            command = self._key(chr(buf[i]))
            if command is not None:
                out.append(command)
            i += 1
        return out

    def _arrow(self, seq: bytes) -> Command | None:
        if len(seq) != 3 or seq[1:2] not in (b"[", b"O"):
            return None
        moves = {
            b"C": self.seek_step,
            b"D": -self.seek_step,
            b"A": 10 * self.seek_step,
            b"B": -10 * self.seek_step,
        }
        by = moves.get(seq[2:3])
        return None if by is None else Seek(by=by)

    @staticmethod
    def _key(key: str) -> Command | None:
        keys: dict[str, Command] = {
            " ": Toggle(),
            "p": Toggle(),
            "+": SetRate(steps=1),
            "=": SetRate(steps=1),
            "-": SetRate(steps=-1),
            "_": SetRate(steps=-1),
            "n": Step(1),
            "N": Step(seconds=1.0),
            "q": Stop(),
        }
        return keys.get(key)
