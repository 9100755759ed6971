"""fleetlog's recording-mode settings of the pLogger block: split, start paused, notes, tags.

Pure code. :func:`read_recording_modes` reads them from a parsed block into
:class:`RecordingModes`; the checks for a note or a tag (:func:`check_note`, :func:`check_tag`)
are shared by the mission file, the command line and the runtime ``NOTE=key:value`` command,
so that every path takes and refuses the same text (docs/compat.md, "Recording modes").

::

    SplitSize     = 500MB       // a new part once the session's files hold this much
    SplitDuration = 10min       // a new part after this long
    StartPaused   = true        // open the session, write nothing until RESUME
    Note          = site:bay    // a note on every session (repeatable)
    Tag           = trial, night
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

from fleetlog.errors import FormatError, MissionError
from fleetlog.moos.settings import moos_bool
from fleetlog.moos.units import parse_duration, parse_size

if TYPE_CHECKING:
    from fleetlog.moos.mission import Param, ProcessBlock

__all__ = [
    "MAX_NOTES",
    "MAX_NOTE_KEY",
    "MAX_NOTE_VALUE",
    "MAX_TAG",
    "MAX_TAGS",
    "MIN_SPLIT_DURATION",
    "MIN_SPLIT_SIZE",
    "RecordingModes",
    "check_note",
    "check_tag",
    "parse_note",
    "read_recording_modes",
]

#: the smallest part a size split makes: smaller parts would be a flood of directories
MIN_SPLIT_SIZE = 1_000_000
#: the shortest part a duration split makes
MIN_SPLIT_DURATION = 1.0
#: notes one session may hold, and their keys' and values' lengths (characters)
MAX_NOTES = 64
MAX_NOTE_KEY = 64
MAX_NOTE_VALUE = 1024
#: tags one session may hold, and their length
MAX_TAGS = 64
MAX_TAG = 64


@dataclass(frozen=True, slots=True)
class RecordingModes:
    """How the recorder cuts and holds its sessions (fleetlog's own settings).

    Attributes:
        split_size: ``SplitSize``: a new part once the open session's files hold this many
            bytes on disk (None: no size split).
        split_duration: ``SplitDuration``: a new part after this many seconds (None: none).
        start_paused: ``StartPaused``: the first session opens paused (nothing written until
            a RESUME).
        notes: ``Note = key:value`` lines, in file order (a later key replaces an earlier).
        tags: ``Tag = a, b`` items, in file order, without repeats.
    """

    split_size: int | None = None
    split_duration: float | None = None
    start_paused: bool = False
    notes: tuple[tuple[str, str], ...] = ()
    tags: tuple[str, ...] = ()


def check_note(key: str, value: str) -> str | None:
    """Return why a note cannot be kept, or None when it can.

    A key is 1-64 printable characters (not only blanks); a value at most 1024 characters
    without control characters other than tab.
    """
    if not key.strip():
        return "a note needs a key (NOTE=key:value)"
    if len(key) > MAX_NOTE_KEY:
        return f"a note's key is {len(key)} characters long: at most {MAX_NOTE_KEY}"
    if not key.isprintable():
        return "a note's key must be printable text"
    if len(value) > MAX_NOTE_VALUE:
        return f"a note's value is {len(value)} characters long: at most {MAX_NOTE_VALUE}"
    if not value.replace("\t", " ").isprintable():
        return "a note's value must be printable text"
    return None


def check_tag(tag: str) -> str | None:
    """Return why a tag cannot be kept, or None (1-64 printable characters, no comma)."""
    if not tag.strip():
        return "a tag is empty"
    if len(tag) > MAX_TAG:
        return f"a tag is {len(tag)} characters long: at most {MAX_TAG}"
    if not tag.isprintable() or "," in tag:
        return "a tag must be printable text without a comma"
    return None


def parse_note(text: str) -> tuple[str, str]:
    """Read ``key:value`` (blanks around each are trimmed; the value may hold ``:``).

    Raises:
        FormatError: no ``:``, or a key or value :func:`check_note` refuses.
    """
    key, sep, value = text.partition(":")
    if not sep:
        msg = f"note {text[:80]!r} is not key:value"
        raise FormatError(msg)
    key, value = key.strip(), value.strip()
    why = check_note(key, value)
    if why is not None:
        raise FormatError(why)
    return key, value


def _checked(param: Param, path: str, error: FormatError) -> MissionError:
    msg = f"{param.name} value {param.value[:80]!r}: {error.reason}"
    return MissionError(msg, path, param.lineno)


def read_recording_modes(
    block: ProcessBlock | None, path: str, *, file_timestamp: bool
) -> RecordingModes:
    """Read the recording-mode settings of the pLogger block.

    Args:
        block: the block (None: the defaults).
        path: the mission file, for messages.
        file_timestamp: the block's ``FileTimeStamp``: splits need time-stamped names.

    Raises:
        MissionError: a size or duration that is not one, below its minimum (1 MB, 1 s), a
            split without time-stamped session names, a note or tag that cannot be kept, or
            more than 64 of either. The message names the file, the line and the setting.
    """
    if block is None:
        return RecordingModes()
    split_size = split_duration = None
    split_param: Param | None = None
    if (param := block.param("SplitSize")) is not None:
        try:
            split_size = parse_size(param.value, name=param.name)
        except FormatError as err:
            raise _checked(param, path, err) from None
        if split_size < MIN_SPLIT_SIZE:
            msg = f"{param.name} value {param.value!r} is below the smallest part, 1MB"
            raise MissionError(msg, path, param.lineno)
        split_param = param
    if (param := block.param("SplitDuration")) is not None:
        try:
            split_duration = parse_duration(param.value, name=param.name)
        except FormatError as err:
            raise _checked(param, path, err) from None
        if split_duration < MIN_SPLIT_DURATION:
            msg = f"{param.name} value {param.value!r} is below the shortest part, 1s"
            raise MissionError(msg, path, param.lineno)
        split_param = split_param or param
    if split_param is not None and not file_timestamp:
        msg = (
            f"{split_param.name} needs time-stamped session names: with FileTimeStamp = false "
            "every part would overwrite the one before"
        )
        raise MissionError(msg, path, split_param.lineno)
    notes: dict[str, str] = {}
    tags: list[str] = []
    for param in block.params:
        lowered = param.name.lower()
        if lowered == "note":
            try:
                key, value = parse_note(param.value)
            except FormatError as err:
                raise _checked(param, path, err) from None
            notes.pop(key, None)
            notes[key] = value
            if len(notes) > MAX_NOTES:
                msg = f"more than {MAX_NOTES} notes"
                raise MissionError(msg, path, param.lineno)
        elif lowered == "tag":
            for item in param.value.split(","):
                tag = item.strip()
                why = check_tag(tag) if tag else None
                if why is not None:
                    msg = f"{param.name} {tag[:80]!r}: {why}"
                    raise MissionError(msg, path, param.lineno)
                if tag and tag not in tags:
                    tags.append(tag)
            if len(tags) > MAX_TAGS:
                msg = f"more than {MAX_TAGS} tags"
                raise MissionError(msg, path, param.lineno)
    paused = block.param("StartPaused")
    return RecordingModes(
        split_size=split_size,
        split_duration=split_duration,
        start_paused=paused is not None and moos_bool(paused.value),
        notes=tuple(notes.items()),
        tags=tuple(tags),
    )
