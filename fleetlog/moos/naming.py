"""Session names, copy-file names and the hint file as pLogger builds them (MOOS_FORMAT.md §1-6).

Pure code: the caller passes every time (a :class:`time.struct_time` or a naive
:class:`~datetime.datetime`, already in local time or UTC as ``UTCLogDirectories`` says) and a
callable for "does this exist"; nothing here reads the clock or the disk.

**Distinct names for sessions started in the same second** (§12). pLogger names a session
``<File>_<D>_<M>_<YYYY>_____<hh>_<mm>_<ss>``, so a second session within the same second
reuses, and truncates, the first one's directory. fleetlog keeps the first name as pLogger
would write it and gives the 2nd, 3rd, … session of that second the suffix ``-2``, ``-3``, …
(:func:`unique_root`), e.g. ``TEST_22_11_2026_____11_06_44-2``:

* no spaces and no dots, so shells, ``ls``, the MOOS-IvP tools and the ``root.alog`` /
  ``stem._ext`` file names see one plain word;
* the pLogger time stamp stays intact and in place, so a search for ``_____11_06_44`` still
  finds it, and plain string order puts ``…_44`` before ``…_44-2``;
* not ``_2``: a script that reads the last three ``_`` fields as ``hh mm ss`` would then read a
  wrong time silently; with ``-2`` its number conversion fails loudly instead.

:func:`parse_session_root` reads both forms. Only time-stamped names get a suffix:
``FileTimeStamp = false`` reuses ``<Path>/<File>`` by design.
"""

from __future__ import annotations

import re
import time
from collections.abc import Callable
from datetime import datetime, timedelta

from fleetlog.errors import FormatError

__all__ = [
    "HINT_FILE_NAME",
    "HINT_KEY",
    "copy_file_name",
    "ctime_text",
    "hint_file_content",
    "normalize_log_path",
    "parse_hint_file",
    "parse_session_root",
    "session_dir",
    "session_root",
    "unique_root",
]

#: The summary file's default name, relative to the recorder's working directory (§5).
HINT_FILE_NAME = ".LastOpenedMOOSLogDirectory"
#: The key written in it (it says ``LoggingDirectory`` although the file name does not).
HINT_KEY = "LastOpenedLoggingDirectory="

_MAX_SESSIONS_PER_SECOND = 9999
_DAYS = ("Mon", "Tue", "Wed", "Thu", "Fri", "Sat", "Sun")  # Python's weekday(): Monday = 0
_MONTHS = ("Jan", "Feb", "Mar", "Apr", "May", "Jun", "Jul", "Aug", "Sep", "Oct", "Nov", "Dec")
_ROOT = re.compile(
    r"(?P<file>.*)_(?P<day>[1-9]\d?)_(?P<month>[1-9]\d?)_(?P<year>[1-9]\d*)"
    r"_____(?P<hour>\d\d)_(?P<minute>\d\d)_(?P<second>\d\d)(?:-(?P<seq>[2-9]|[1-9]\d+))?",
    re.DOTALL,
)


def _fields(when: time.struct_time | datetime) -> tuple[int, int, int, int, int, int, int]:
    """Return (year, month, day, hour, minute, second, weekday with Monday = 0)."""
    if isinstance(when, datetime):
        return (
            when.year,
            when.month,
            when.day,
            when.hour,
            when.minute,
            when.second,
            when.weekday(),
        )
    return (
        when.tm_year,
        when.tm_mon,
        when.tm_mday,
        when.tm_hour,
        when.tm_min,
        when.tm_sec,
        when.tm_wday,
    )


def session_root(file: str, when: time.struct_time | datetime | None, timestamp: bool) -> str:
    """Return a session's root name, as pLogger's ``MakeLogName`` builds it (§1.1).

    Args:
        file: the ``File`` parameter (default ``MOOSLog``).
        when: the session's opening time, local or UTC as configured; unused without
            time stamps.
        timestamp: ``FileTimeStamp``; without it the root is ``file`` exactly.

    Returns:
        ``"%s_%d_%d_%d_____%.2d_%.2d_%.2d"`` of file, day, month, year, hour, minute, second
        (e.g. ``MOOSLog_3_2_2025_____09_05_07``), or ``file``.

    Raises:
        FormatError: if a time stamp is asked for without a time.
    """
    if not timestamp:
        return file
    if when is None:
        msg = f"session root {file!r}: a time-stamped name needs the opening time"
        raise FormatError(msg)
    year, month, day, hour, minute, second, _ = _fields(when)
    return "%s_%d_%d_%d_____%.2d_%.2d_%.2d" % (  # noqa: UP031 - pLogger's own format
        file,
        day,
        month,
        year,
        hour,
        minute,
        second,
    )


def normalize_log_path(path: str) -> str:
    """Remove exactly one trailing ``/``, as pLogger does with ``Path`` (§1.2).

    ``"./"`` becomes ``"."``, ``"/data/logs/"`` becomes ``"/data/logs"``, ``"a//"`` becomes
    ``"a/"`` and ``"/"`` becomes ``""`` (so the session lands in ``/<root>``).
    """
    return path[:-1] if path.endswith("/") else path


def session_dir(path: str, root: str) -> str:
    """Return the session directory string, ``path + "/" + root`` (§1.2).

    This exact string goes into the banners, LOGGER_DIRECTORY and the hint file.

    Args:
        path: the log path after :func:`normalize_log_path`.
        root: the session root (:func:`session_root`, perhaps :func:`unique_root`).
    """
    return path + "/" + root


def unique_root(root: str, exists: Callable[[str], bool]) -> str:
    """Return ``root``, or ``root-2``, ``root-3``, … : the first one that does not exist yet.

    The suffix scheme is described in the module docstring. Use it for time-stamped roots only.

    Args:
        root: a time-stamped session root.
        exists: tells whether a candidate root is taken (the caller decides where to look,
            usually ``os.path.exists(session_dir(path, candidate))``).

    Returns:
        A root for which ``exists`` returned False.

    Raises:
        FormatError: if 9999 candidates are all taken.
    """
    if not exists(root):
        return root
    for seq in range(2, _MAX_SESSIONS_PER_SECOND + 1):
        candidate = f"{root}-{seq}"
        if not exists(candidate):
            return candidate
    msg = f"session root {root!r}: {_MAX_SESSIONS_PER_SECOND} sessions already in that second"
    raise FormatError(msg)


def parse_session_root(name: str) -> tuple[str, datetime] | None:
    """Split a time-stamped session root (or directory name) into ``File`` and its time.

    Reads pLogger's names and fleetlog's ``-N`` suffix. To order sessions of the same second,
    the n-th session's time carries ``n - 1`` microseconds (the plain name has 0), so sorting
    by the returned time sorts sessions in the order they were opened. A leap second (``60``)
    is read as the next second.

    Args:
        name: e.g. ``LOG_ALPHA_19_6_2025_____12_04_50`` or ``TEST_22_11_2026_____11_06_44-2``.

    Returns:
        ``(file, naive datetime)``, or None if the name is not a time-stamped root (a
        ``FileTimeStamp = false`` name, or an impossible date).
    """
    m = _ROOT.fullmatch(name)
    if m is None:
        return None
    seq = int(m.group("seq") or 1)
    second = int(m.group("second"))
    try:
        when = datetime(
            int(m.group("year")),
            int(m.group("month")),
            int(m.group("day")),
            int(m.group("hour")),
            int(m.group("minute")),
            min(second, 59),
            seq - 1,
        )
    except ValueError:
        return None
    if second == 60:  # a leap second
        when += timedelta(seconds=1)
    elif second > 60:
        return None
    return m.group("file"), when


def copy_file_name(path: str) -> str:
    """Return the name COPY_FILE_REQUEST gives a copy inside the session directory (§6.2).

    The path is split at its last ``/``; the file part at its last ``.`` into stem and
    extension (``MOOSFileParts``). The copy is ``stem + "." + "_" + ext``, or
    ``stem + "._bak"`` without an extension. A dot in a directory component does not count
    (``dir.x/file`` gives ``file._bak``, as in MOOS), nor does a final dot
    (``file.`` gives ``file._bak``); a leading one does (``.bashrc`` gives ``._bashrc``).

    Args:
        path: the requested path, as received (spaces already stripped by the command parser).

    Returns:
        The copy's file name, without directory: ``alpha.bhv`` gives ``alpha._bhv``,
        ``/etc/hostname`` gives ``hostname._bak``, ``a/b.c.d`` gives ``b.c._d``.

    Raises:
        FormatError: if the path names no file (empty, or ending in ``/``); pLogger would
            write an empty ``._bak`` there.
    """
    file = path.rpartition("/")[2]
    if not file:
        msg = f"copy request {path!r} names no file"
        raise FormatError(msg)
    stem, dot, ext = file.rpartition(".")
    if not dot:
        stem, ext = file, ""
    return stem + "." + ("_" + ext if ext else "_bak")


def hint_file_content(directory: str) -> str:
    """Return the summary ("last opened directory") file's text (§5).

    That is ``LastOpenedLoggingDirectory=<dir>`` and a newline, e.g.
    ``LastOpenedLoggingDirectory=./MOOSLog_3_2_2025_____09_05_07`` for the default path.
    """
    return HINT_KEY + directory + "\n"


def parse_hint_file(text: str, path: str | None = None) -> str:
    """Return the directory a summary file names.

    One line ``LastOpenedLoggingDirectory=<dir>``; a missing final newline and a CR LF line
    ending are accepted.

    Args:
        text: the file's content.
        path: the file's name, for error messages.

    Raises:
        FormatError: if the text is anything else (another key, more lines, no directory).
    """
    body = text
    if body.endswith("\r\n"):
        body = body[:-2]
    elif body.endswith("\n"):
        body = body[:-1]
    if not body.startswith(HINT_KEY):
        msg = f"expected {HINT_KEY!r} at the start, found {body[:40]!r}"
        raise FormatError(msg, path, 1)
    directory = body[len(HINT_KEY) :]
    if "\n" in directory or "\r" in directory:
        msg = "expected one line, found more"
        raise FormatError(msg, path, 1)
    if not directory:
        msg = "no directory after " + HINT_KEY
        raise FormatError(msg, path, 1)
    return directory


def ctime_text(when: time.struct_time | datetime) -> str:
    """Return a time in C's ``ctime`` layout without the newline, for ``FILE OPENED ON`` (§2.1).

    English day and month names whatever the locale, the day of the month padded with a space:
    ``Thu Jan  1 00:00:00 1970``.
    """
    year, month, day, hour, minute, second, weekday = _fields(when)
    return "%s %s %2d %.2d:%.2d:%.2d %d" % (  # noqa: UP031 - C's asctime format
        _DAYS[weekday],
        _MONTHS[month - 1],
        day,
        hour,
        minute,
        second,
        year,
    )
