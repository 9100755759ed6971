r"""pLogger's configuration: the ``ProcessConfig = pLogger`` block read into a LoggerConfig.

Pure code. :func:`logger_config` reads a parsed :class:`~fleetlog.moos.mission.Mission` (what
:meth:`Mission.logger_config` returns); :func:`parse_log_spec` parses ``Log =`` values and
PLOGGER_CMD's ``LOG_REQUEST`` (MOOS_FORMAT.md §6.5). Numbers that are not numbers, and values
pLogger could not use, raise :class:`~fleetlog.errors.MissionError` naming the file, the line
and the setting.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Literal

from fleetlog.errors import MissionError
from fleetlog.moos.keep_settings import (
    DiskSettings,
    SnapshotSettings,
    read_disk_settings,
    read_snapshot_settings,
)
from fleetlog.moos.recording_modes import RecordingModes, read_recording_modes
from fleetlog.moos.settings import FLOAT_RE as _FLOAT_RE
from fleetlog.moos.settings import INT_RE as _INT_RE
from fleetlog.moos.settings import SQUEEZE_ALL as _SQUEEZE_ALL
from fleetlog.moos.settings import TRIM as _TRIM
from fleetlog.moos.settings import c_atof as _c_atof
from fleetlog.moos.settings import key as _key
from fleetlog.moos.settings import moos_bool as _moos_bool
from fleetlog.moos.settings import squeeze as _squeeze

if TYPE_CHECKING:
    from fleetlog.moos.mission import Mission, Param, ProcessBlock

__all__ = [
    "ALWAYS_LOGGED",
    "ALWAYS_OMITTED",
    "DEFAULT_LOG_PERIOD",
    "MAX_DOUBLE_PRECISION",
    "MAX_DYNAMIC_COLUMNS",
    "MAX_FILE_BYTES",
    "MIN_SYNC_PERIOD",
    "CompressMode",
    "LogSpec",
    "LoggerConfig",
    "VariantName",
    "logger_config",
    "parse_log_spec",
]

#: pLogger subscribes to these itself (period 0); a ``Log =`` line for them is ignored (§2.2).
ALWAYS_LOGGED = ("MOOS_DEBUG", "MOOS_SYSTEM")
#: The period of a ``Log =`` entry without ``@`` (§6.5).
DEFAULT_LOG_PERIOD = 2.0
#: pLogger's minimum slog period (§3.1).
MIN_SYNC_PERIOD = 0.1
#: Variables wildcard logging never takes (§6.4).
ALWAYS_OMITTED = ("MISSION_FILE",)

#: the most decimals ``DoublePrecision`` may ask for: a double has 17 significant digits, and
#: 30 decimals still show 1e-13 to 17 digits while keeping every line short
MAX_DOUBLE_PRECISION = 30
#: the most ``DYNAMIC_`` columns a mission may reserve (each one is a column of every row)
MAX_DYNAMIC_COLUMNS = 1000
#: the longest ``File``: the session's name adds a time stamp (24 bytes), a ``-N`` suffix and
#: an extension (``.alog.zst``) and must stay one file name (255 bytes)
MAX_FILE_BYTES = 200
#: one component of a path, and a whole path, as Linux allows them
MAX_NAME_BYTES = 255
MAX_PATH_BYTES = 4095

#: How alogs are compressed: ``CompressAlogs = true`` (or ``gzip``) → gzip as pLogger writes it,
#: ``= zstd`` → zstd, fleetlog's explicit choice (DESIGN_NOTES "Compression").
CompressMode = Literal["none", "zstd", "gzip"]
#: Which pLogger's on-disk variant to write (``alog.Variant`` values).
VariantName = Literal["ivp", "em"]

# --------------------------------------------------------------------------------------------
# Log = VAR @ period [NOSYNC] [MONITOR]


@dataclass(frozen=True, slots=True)
class LogSpec:
    """One ``Log =`` entry or ``LOG_REQUEST`` (§6.5).

    Attributes:
        var: the MOOS variable name.
        period: the minimum interval between delivered posts, in seconds (0: every post).
        sync: the variable is a ``.slog`` column (no ``NOSYNC`` flag).
        monitor: pLogger checks that the variable keeps appearing (``MONITOR`` flag, §6.6).
    """

    var: str
    period: float = DEFAULT_LOG_PERIOD
    sync: bool = True
    monitor: bool = False

    def to_text(self) -> str:
        """Return the entry as ``VAR @ period [NOSYNC] [MONITOR]``; parsing it gives it back."""
        parts = [self.var, "@", repr(self.period)]
        if not self.sync:
            parts.append("NOSYNC")
        if self.monitor:
            parts.append("MONITOR")
        return " ".join(parts)


def parse_log_spec(text: str, *, lineno: int | None = None, path: str | None = None) -> LogSpec:
    """Parse a ``Log =`` value or a ``LOG_REQUEST`` value as pLogger does (§6.5, §12).

    All whitespace is removed; ``VAR`` is the text before the first ``@``; the period is C's
    ``atof`` of the rest up to its first comma (0 when it does not start with a number, 2.0
    when that part is empty or there is no ``@``). ``NOSYNC`` and ``MONITOR`` anywhere after
    the ``@`` are flags in any case (pLogger only knows upper case; §12 fixes that). Without
    an ``@`` the flags are glued onto the name, as in pLogger: ``X NOSYNC`` logs ``XNOSYNC``.

    Args:
        text: the value, for example ``NAV_X @ 0.5 NOSYNC``.
        lineno: the mission line, for error messages.
        path: the mission file, for error messages.

    Returns:
        The parsed entry.

    Raises:
        MissionError: no variable name, a name with unprintable characters (a byte that is
            not UTF-8 is fine), or a negative or non-finite period.
    """
    squeezed = text.translate(_SQUEEZE_ALL)
    var, at, rest = squeezed.partition("@")
    if not var:
        msg = f"log entry {text.strip()!r} names no variable before '@'"
        raise MissionError(msg, path, lineno)
    if not var.isprintable() and not all(c.isprintable() or "\udc80" <= c <= "\udcff" for c in var):
        # A control character or a line separator would break the slog's columns and lines.
        msg = f"log entry {text.strip()!r} names a variable holding unprintable characters"
        raise MissionError(msg, path, lineno)
    period = DEFAULT_LOG_PERIOD
    head = rest.partition(",")[0]
    if head:
        period = _c_atof(head)
    if not math.isfinite(period):
        msg = f"log entry {text.strip()!r} has a period that is not a finite number"
        raise MissionError(msg, path, lineno)
    if period < 0:
        msg = f"log entry {text.strip()!r} has a negative period"
        raise MissionError(msg, path, lineno)
    flags = rest.upper() if at else ""
    return LogSpec(var, period, sync="NOSYNC" not in flags, monitor="MONITOR" in flags)


# --------------------------------------------------------------------------------------------
# pLogger's configuration

_NO_MODES = RecordingModes()


@dataclass(frozen=True, slots=True)
class LoggerConfig:
    """Everything pLogger reads from a mission file (§1, §3.1, §5, §6.4-6.7).

    The field defaults are pLogger's own with a mission file open; :meth:`default` gives the
    configuration without one. Block parameters are read from ``ProcessConfig = <app_name>``
    (names in any case); booleans are true for ``true`` in any case or a number above 0.

    Attributes:
        app_name: the block's name (``pLogger``, ``pLogger_B``…).
        file: ``File``, the stem of the session root name.
        path: file-scope ``GlobalLogPath``, else ``Path``, else ``./``; then exactly one
            trailing ``/`` is removed (``./`` → ``.``, ``/`` → ``""``).
        file_timestamp: ``FileTimeStamp``.
        utc_log_directories: ``UTCLogDirectories``.
        async_log: ``AsyncLog``; always true when wildcard logging is on.
        sync_log: ``SyncLog = true [@ period]``: only the word ``true`` enables it (§3.1).
        sync_period: the slog period after ``@`` (default 1.0, at least 0.1).
        double_precision: ``DoublePrecision``, decimals of double values.
        log_aux_src: ``LogAuxSrc``.
        mark_external_community_messages: ``MarkExternalCommunityMessages``.
        mark_data_type: ``MarkDataType``.
        compress_alogs: ``CompressAlogs``: any true value or ``gzip`` → ``"gzip"`` (pLogger's
            ``.alog.gz``, which MOOS users' tools open), ``zstd`` → ``"zstd"`` (fleetlog's
            explicit choice), anything else → ``"none"``.
        dynamic_sync_log_columns: ``DynamicSyncLogColumns`` (0 with a mission file).
        wildcard_logging: ``WildcardLogging``; true when the mission has no block for
            ``app_name`` at all.
        wildcard_patterns: every ``WildcardPattern`` (any case and spelling, may repeat,
            comma-separated, whitespace removed), in file order.
        wildcard_omit_patterns: ``MISSION_FILE`` then every ``WildcardOmitPattern``.
        wildcard_exclusion_log: ``WildcardExclusionLog``.
        logging_directory_summary_file: ``LoggingDirectorySummaryFile`` (§5).
        log_specs: the ``Log`` entries in file order; for a repeated variable the first
            wins, and ``MOOS_DEBUG``/``MOOS_SYSTEM`` are left out (always logged, §2.2).
        community: the file-scope ``Community``, or None.
        helm_task_file: ``TaskFile`` of the ``pHelm`` (else ``pHelmIvP``) block, or None; it
            is copied to ``._hoof`` (§1.3).
        variant: fleetlog's own block parameter ``LogFormat = ivp|em`` (default ``ivp``):
            which pLogger's on-disk variant to write (§2.3; ``fleetlog.moos.alog.Variant``).
        copy_file_dirs: fleetlog's own block parameter ``CopyFileDirs = dir1, dir2`` (may
            repeat): extra directories COPY_FILE_REQUEST may read from.
        moos_time_warp: the file-scope ``MOOSTimeWarp`` (default 1.0).
        fsync_interval: fleetlog's own block parameter ``FsyncInterval = seconds`` (default
            1): how often the open session's files are synced to the disk (``0``: only when
            the session closes).
        modes: fleetlog's recording modes (``SplitSize``, ``SplitDuration``, ``StartPaused``,
            ``Note``, ``Tag``; :mod:`fleetlog.moos.recording_modes`).
        snapshot: snapshot mode (``SnapshotSeconds``...; :mod:`fleetlog.moos.keep_settings`),
            None when off.
        disk: the disk guard and retention (``MinFreeDisk``, ``KeepSessions``,
            ``MaxLogSize``).
    """

    app_name: str = "pLogger"
    file: str = "MOOSLog"
    path: str = "."
    file_timestamp: bool = True
    utc_log_directories: bool = False
    async_log: bool = True
    sync_log: bool = False
    sync_period: float = 1.0
    double_precision: int = 5
    log_aux_src: bool = False
    mark_external_community_messages: bool = False
    mark_data_type: bool = False
    compress_alogs: CompressMode = "none"
    dynamic_sync_log_columns: int = 0
    wildcard_logging: bool = False
    wildcard_patterns: tuple[str, ...] = ()
    wildcard_omit_patterns: tuple[str, ...] = ALWAYS_OMITTED
    wildcard_exclusion_log: bool = False
    logging_directory_summary_file: str = ".LastOpenedMOOSLogDirectory"
    log_specs: tuple[LogSpec, ...] = ()
    community: str | None = None
    helm_task_file: str | None = None
    variant: VariantName = "ivp"
    copy_file_dirs: tuple[str, ...] = ()
    moos_time_warp: float = 1.0
    fsync_interval: float = 1.0
    modes: RecordingModes = _NO_MODES
    snapshot: SnapshotSettings | None = None
    disk: DiskSettings = field(default_factory=DiskSettings)

    @classmethod
    def default(cls, app_name: str = "pLogger") -> LoggerConfig:
        """Return the configuration pLogger uses without a mission file (§12).

        It logs to ``.`` with time-stamped names, with wildcard logging on and 10 dynamic
        slog columns.
        """
        return cls(app_name=app_name, wildcard_logging=True, dynamic_sync_log_columns=10)

    @property
    def sync_columns(self) -> tuple[str, ...]:
        """The ``.slog`` columns from ``Log`` entries (those without ``NOSYNC``), in order."""
        return tuple(spec.var for spec in self.log_specs if spec.sync)

    @property
    def monitored(self) -> tuple[str, ...]:
        """The variables logged with ``MONITOR``."""
        return tuple(spec.var for spec in self.log_specs if spec.monitor)


class _Reader:
    """Typed reads of one block's parameters, raising MissionError on bad numbers."""

    def __init__(self, block: ProcessBlock | None, path: str) -> None:
        self.block = block
        self.path = path

    def param(self, name: str) -> Param | None:
        return None if self.block is None else self.block.param(name)

    def string(self, name: str, default: str) -> str:
        param = self.param(name)
        return default if param is None else param.value

    def boolean(self, name: str, default: bool) -> bool:
        param = self.param(name)
        return default if param is None else _moos_bool(param.value)

    def integer(self, name: str, default: int, high: int) -> int:
        param = self.param(name)
        if param is None:
            return default
        if not _INT_RE.fullmatch(param.value):
            msg = f"{param.name} value {param.value!r} is not an integer"
            raise MissionError(msg, self.path, param.lineno)
        value = int(param.value)
        if value < 0:
            msg = f"{param.name} value {param.value!r} is negative"
            raise MissionError(msg, self.path, param.lineno)
        if value > high:
            msg = f"{param.name} value {param.value!r} is too large: at most {high}"
            raise MissionError(msg, self.path, param.lineno)
        return value

    def file_name(self, name: str, default: str, *, stem: bool = False) -> str:
        """A setting that names a file or a directory (``stem``: ``File``)."""
        param = self.param(name)
        if param is None:
            return default
        check_path(param, self.path, stem=stem)
        return param.value

    def raw_list(self, name: str) -> tuple[str, ...]:
        if self.block is None:
            return ()
        items: list[str] = []
        for param in self.block.raw_values(name):
            items.extend(item for item in param.value.split(",") if item)
        return tuple(items)


def check_path(param: Param, path: str, *, stem: bool = False) -> None:
    """Refuse a path no filesystem could take.

    Args:
        param: the setting.
        path: the mission file, for the message.
        stem: the value is ``File``, whose last component gets a time stamp and an extension
            (so at most :data:`MAX_FILE_BYTES`).

    Raises:
        MissionError: the value is not UTF-8 text, a component is longer than 255 bytes (the
            last one of a ``stem`` longer than :data:`MAX_FILE_BYTES`), or the whole is longer
            than 4095.
    """
    value = param.value
    try:
        raw = value.encode("utf-8")
    except UnicodeEncodeError:
        msg = f"{param.name} value {value!r} is not UTF-8 text"
        raise MissionError(msg, path, param.lineno) from None
    if len(raw) > MAX_PATH_BYTES:
        msg = f"{param.name} value is {len(raw)} bytes long: at most {MAX_PATH_BYTES}"
        raise MissionError(msg, path, param.lineno)
    parts = raw.split(b"/")
    for index, part in enumerate(parts):
        limit = MAX_FILE_BYTES if stem and index == len(parts) - 1 else MAX_NAME_BYTES
        if len(part) > limit:
            shown = part[:24].decode() + "…"
            msg = (
                f"{param.name} value has a component of {len(part)} bytes ({shown!r}): "
                f"at most {limit}"
            )
            raise MissionError(msg, path, param.lineno)


def _sync_log(reader: _Reader) -> tuple[bool, float]:
    param = reader.param("SyncLog")
    if param is None:
        return False, 1.0
    word, _, rest = _squeeze(param.value).partition("@")
    period = 1.0
    if rest:
        if not _FLOAT_RE.fullmatch(rest):
            msg = f"{param.name} period {rest!r} is not a number"
            raise MissionError(msg, reader.path, param.lineno)
        period = max(float(rest), MIN_SYNC_PERIOD)
        if not math.isfinite(period):
            msg = f"{param.name} period {rest!r} is not a finite number"
            raise MissionError(msg, reader.path, param.lineno)
    return _key(word) == "TRUE", period


def _compress_mode(reader: _Reader) -> CompressMode:
    value = reader.string("CompressAlogs", "")
    lowered = value.lower()
    if lowered == "zstd":
        return "zstd"
    if lowered == "gzip" or _moos_bool(value):
        return "gzip"
    return "none"


def _fsync_interval(reader: _Reader) -> float:
    param = reader.param("FsyncInterval")
    if param is None:
        return 1.0
    value = param.value.strip()
    if not _FLOAT_RE.fullmatch(value) or not math.isfinite(float(value)) or float(value) < 0:
        msg = f"{param.name} value {param.value!r} is not a number of seconds (0 or more)"
        raise MissionError(msg, reader.path, param.lineno)
    return float(value)


def _variant(reader: _Reader) -> VariantName:
    param = reader.param("LogFormat")
    if param is None:
        return "ivp"
    lowered = param.value.lower()
    if lowered == "ivp":
        return "ivp"
    if lowered == "em":
        return "em"
    msg = f"{param.name} value {param.value!r} is neither 'ivp' nor 'em'"
    raise MissionError(msg, reader.path, param.lineno)


def _log_specs(reader: _Reader) -> tuple[LogSpec, ...]:
    if reader.block is None:
        return ()
    specs: list[LogSpec] = []
    seen = set(ALWAYS_LOGGED)
    for param in reader.block.raw_values("Log"):
        spec = parse_log_spec(param.value, lineno=param.lineno, path=reader.path)
        if spec.var not in seen:
            seen.add(spec.var)
            specs.append(spec)
    return tuple(specs)


def _time_warp(mission: Mission) -> float:
    param = mission.global_param("MOOSTimeWarp")
    if param is None or not param.value:
        return 1.0
    if not _FLOAT_RE.fullmatch(param.value):
        msg = f"{param.name} value {param.value!r} is not a number"
        raise MissionError(msg, mission.path, param.lineno)
    warp = float(param.value)
    if not math.isfinite(warp):
        msg = f"{param.name} value {param.value!r} is not a finite number"
        raise MissionError(msg, mission.path, param.lineno)
    if warp <= 0:
        msg = f"{param.name} value {param.value!r} is not greater than 0"
        raise MissionError(msg, mission.path, param.lineno)
    return warp


def _helm_task_file(mission: Mission) -> str | None:
    for app in ("pHelm", "pHelmIvP"):
        block = mission.block(app)
        if block is not None and (param := block.param("TaskFile")) is not None:
            check_path(param, mission.path)
            return param.value
    return None


def logger_config(mission: Mission, app_name: str = "pLogger") -> LoggerConfig:
    """Return pLogger's configuration for ``app_name``'s block (:meth:`Mission.logger_config`)."""
    block = mission.block(app_name)
    reader = _Reader(block, mission.path)

    global_path = mission.global_param("GlobalLogPath")
    if global_path is not None and global_path.value:
        check_path(global_path, mission.path)
        path = global_path.value
    else:
        path = reader.file_name("Path", "./")
    if path.endswith("/"):
        path = path[:-1]

    sync_log, sync_period = _sync_log(reader)
    wildcard = reader.boolean("WildcardLogging", False) if block is not None else True
    copy_dirs: list[str] = []
    for param in block.params if block is not None else ():
        if _key(param.name) == "COPYFILEDIRS":
            check_path(param, mission.path)
            copy_dirs.extend(
                item.strip(_TRIM) for item in param.value.split(",") if item.strip(_TRIM)
            )

    file_timestamp = reader.boolean("FileTimeStamp", True)
    return LoggerConfig(
        app_name=app_name,
        file=reader.file_name("File", "MOOSLog", stem=True),
        path=path,
        file_timestamp=file_timestamp,
        utc_log_directories=reader.boolean("UTCLogDirectories", False),
        async_log=wildcard or reader.boolean("AsyncLog", True),
        sync_log=sync_log,
        sync_period=sync_period,
        double_precision=reader.integer("DoublePrecision", 5, MAX_DOUBLE_PRECISION),
        log_aux_src=reader.boolean("LogAuxSrc", False),
        mark_external_community_messages=reader.boolean("MarkExternalCommunityMessages", False),
        mark_data_type=reader.boolean("MarkDataType", False),
        compress_alogs=_compress_mode(reader),
        dynamic_sync_log_columns=reader.integer("DynamicSyncLogColumns", 0, MAX_DYNAMIC_COLUMNS),
        wildcard_logging=wildcard,
        wildcard_patterns=reader.raw_list("WildcardPattern"),
        wildcard_omit_patterns=ALWAYS_OMITTED + reader.raw_list("WildcardOmitPattern"),
        wildcard_exclusion_log=reader.boolean("WildcardExclusionLog", False),
        logging_directory_summary_file=reader.file_name(
            "LoggingDirectorySummaryFile", ".LastOpenedMOOSLogDirectory"
        ),
        log_specs=_log_specs(reader),
        community=mission.community,
        helm_task_file=_helm_task_file(mission),
        variant=_variant(reader),
        copy_file_dirs=tuple(copy_dirs),
        moos_time_warp=_time_warp(mission),
        fsync_interval=_fsync_interval(reader),
        modes=read_recording_modes(block, mission.path, file_timestamp=file_timestamp),
        snapshot=read_snapshot_settings(block, mission.path),
        disk=read_disk_settings(block, mission.path),
    )
