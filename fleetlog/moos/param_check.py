"""Unknown pLogger-block parameters and ``Log =`` periods that are not numbers: warnings.

Pure code. pLogger ignores a parameter it does not know (``WildcardLoging = true`` leaves
wildcard logging off) and reads a ``Log =`` period with C's ``atof`` (``@ fast`` is 0: every
post). :func:`check_logger_block` names each such line, the closest known parameter and the
period pLogger would use; ``fleetlog record`` prints them as warnings, or refuses to start
with ``--strict``.
"""

from __future__ import annotations

import difflib
import re
from typing import TYPE_CHECKING

from fleetlog.errors import MissionError
from fleetlog.moos.settings import FLOAT_RE, SQUEEZE_ALL, c_atof

if TYPE_CHECKING:
    from fleetlog.moos.mission import ProcessBlock

__all__ = ["CMOOSAPP_PARAMETERS", "FLEETLOG_PARAMETERS", "PLOGGER_PARAMETERS", "check_logger_block"]

#: read by pLogger itself (MOOS_FORMAT.md §6.7; ``GlobalLogPath`` is read anywhere in the file)
PLOGGER_PARAMETERS = (
    "AsyncLog",
    "CompressAlogs",
    "DoublePrecision",
    "DynamicSyncLogColumns",
    "File",
    "FileTimeStamp",
    "GlobalLogPath",
    "Log",
    "LogAuxSrc",
    "LoggingDirectorySummaryFile",
    "MarkDataType",
    "MarkExternalCommunityMessages",
    "Path",
    "SyncLog",
    "UTCLogDirectories",
    "WildcardExclusionLog",
    "WildcardLogging",
    "WildcardOmitPattern",
    "WildcardPattern",
)
#: read by every MOOS app (CMOOSApp), pLogger included (MOOS_FORMAT.md §6.7)
CMOOSAPP_PARAMETERS = (
    "AppTick",
    "CatchCommandMessages",
    "CommsTick",
    "IterateMode",
    "MaxAppTick",
    "MOOSTimeWarp",
    "ServerHost",
    "ServerPort",
    "SortMailByTime",
    "UseMOOSComms",
)
#: fleetlog's own (docs/compat.md)
FLEETLOG_PARAMETERS = (
    "CopyFileDirs",
    "FsyncInterval",
    "KeepSessions",
    "LogFormat",
    "MaxLogSize",
    "MinFreeDisk",
    "Note",
    "SnapshotAfter",
    "SnapshotMemory",
    "SnapshotSeconds",
    "SnapshotTrigger",
    "SplitDuration",
    "SplitSize",
    "StartPaused",
    "Tag",
)
_KNOWN = {
    name.upper(): name for name in (*PLOGGER_PARAMETERS, *CMOOSAPP_PARAMETERS, *FLEETLOG_PARAMETERS)
}
#: the flags a ``Log =`` value may carry after its period (any case)
_FLAGS = re.compile("NOSYNC|MONITOR", re.IGNORECASE)
#: at most this many warnings are listed (a mission of garbage lines says so once)
MAX_WARNINGS = 50


def _closest(name: str) -> str | None:
    found = difflib.get_close_matches(name.upper(), list(_KNOWN), n=1, cutoff=0.6)
    return _KNOWN[found[0]] if found else None


def check_logger_block(block: ProcessBlock | None, path: str) -> list[MissionError]:
    """Return a warning for each line of the pLogger block that pLogger reads silently wrong.

    Each is a :class:`~fleetlog.errors.MissionError` (not raised) naming the file and line:
    a parameter neither pLogger, CMOOSApp nor fleetlog knows, with the closest known name;
    a ``Log =`` line whose period is not a number, with the period pLogger uses (``atof``).
    At most :data:`MAX_WARNINGS`; the last then says how many more there were.
    """
    if block is None:
        return []
    found: list[MissionError] = []
    for param in block.params:
        if param.name.upper() in _KNOWN:
            continue
        closest = _closest(param.name)
        hint = f"did you mean {closest!r}?" if closest else "no known parameter is close"
        shown = param.name if len(param.name) <= 80 else param.name[:80] + "…"
        msg = f"unknown pLogger parameter {shown!r} is ignored ({hint})"
        found.append(MissionError(msg, path, param.lineno))
    written = {param.lineno: param.value for param in block.params}
    for param in block.raw_values("Log"):
        head = param.value.translate(SQUEEZE_ALL).partition("@")[2].partition(",")[0]
        period = _FLAGS.sub("", head)
        if not period or FLOAT_RE.fullmatch(period):
            continue
        used = c_atof(head)
        shown = period if len(period) <= 40 else period[:40] + "…"
        line = written.get(param.lineno, param.value)[:80]
        msg = (
            f"Log = {line}: the period {shown!r} is not a number; "
            f"pLogger reads it as {used:g} s" + (" (every post)" if used == 0 else "")
        )
        found.append(MissionError(msg, path, param.lineno))
    found.sort(key=lambda err: err.lineno or 0)
    if len(found) > MAX_WARNINGS:
        more = len(found) - MAX_WARNINGS + 1
        found = found[: MAX_WARNINGS - 1]
        found.append(MissionError(f"and {more} more warnings like these", path))
    return found
