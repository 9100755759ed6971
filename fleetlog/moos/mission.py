r"""MOOS ``.moos`` mission files and pLogger's configuration block (MOOS_FORMAT.md §9, §1, §6).

Pure code: :func:`parse_mission` takes the file's text (it never opens a file) and returns a
:class:`Mission`; :meth:`Mission.logger_config` turns the pLogger block into a
:class:`LoggerConfig`; :func:`parse_log_spec` parses ``Log =`` values and PLOGGER_CMD's
``LOG_REQUEST`` (§6.5).

The reading follows MOOS's ``CMOOSFileReader`` and ``CProcessConfigReader``:

* The file is split at ``\n`` only; leading whitespace and blank lines are skipped, and a
  line whose first characters are ``//`` is a comment.
* On each line, the first ``"…"`` pair is unwrapped (the quotes are removed) and a ``//``
  inside it does not start a comment; any other ``//`` ends the line.
* ``define: NAME = value`` lines (anywhere in the file; all whitespace removed from name and
  value; the last definition of a name wins, as MOOS's map does) feed ``${NAME}``, which is
  expanded on every other line from the defines, else from ``env``, in one pass (an
  expanded value is not expanded again).
* ``ProcessConfig = NAME`` (compared case-insensitively with blanks removed) on its own line,
  then a line beginning with ``{``, parameter lines ``name = value``, and a line beginning
  with ``}``. Text after that ``{`` or ``}`` on the same line is ignored, as in MOOS.
* Block parameters: names compared case-insensitively, values trimmed at the ends, lines
  with an empty value ignored, the first occurrence wins. The *raw* form (``Log``,
  ``WildcardPattern``, ``WildcardOmitPattern``) has every space, tab and CR removed.
* File-scope values (``GetValue``: ``Community``, ``GlobalLogPath``, ``MOOSTimeWarp``…)
  come from the first ``name = value`` line anywhere in the file, blocks included, with
  every space, tab and CR removed from the value.

Where MOOS only prints a warning and carries on (and pLogger then silently does something
else, such as wildcard-logging everything because its block was never closed), fleetlog
raises :class:`~fleetlog.errors.MissionError` naming the file, the line and what is wrong:
an unclosed block, a ``ProcessConfig`` line without ``{`` after it, a stray ``{`` or ``}``,
a nested ``ProcessConfig``, a block line without ``=``, an undefined ``${VAR}`` and numbers
that are not numbers. Two MOOS accidents are deliberately not reproduced: ``define:`` only
counts at the start of a line (MOOS finds it anywhere in a line), and a ``//`` inside the
first quoted pair is always protected (MOOS's check has a shift typo, ``nC<<nS2``, that very
rarely lets it through).
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Literal, NamedTuple

from fleetlog.errors import MissionError

__all__ = [
    "ALWAYS_LOGGED",
    "ALWAYS_OMITTED",
    "DEFAULT_LOG_PERIOD",
    "MIN_SYNC_PERIOD",
    "CompressMode",
    "LogSpec",
    "LoggerConfig",
    "Mission",
    "Param",
    "ProcessBlock",
    "VariantName",
    "parse_log_spec",
    "parse_mission",
]

#: pLogger subscribes to these itself (period 0); a ``Log =`` line for them is ignored (§2.2).
ALWAYS_LOGGED = ("MOOS_DEBUG", "MOOS_SYSTEM")
#: The period of a ``Log =`` entry without ``@`` (§6.5).
DEFAULT_LOG_PERIOD = 2.0
#: pLogger's minimum slog period (§3.1).
MIN_SYNC_PERIOD = 0.1
#: Variables wildcard logging never takes (§6.4).
ALWAYS_OMITTED = ("MISSION_FILE",)

#: How alogs are compressed: ``CompressAlogs = true`` → zstd, ``= gzip`` → gzip (§12).
CompressMode = Literal["none", "zstd", "gzip"]
#: Which pLogger's on-disk variant to write (``alog.Variant`` values).
VariantName = Literal["ivp", "em"]

_PROCESS_CONFIG = "PROCESSCONFIG="
_DEFINE = "define:"
# ``>> std::ws`` skips every C isspace character; MOOSTrimWhiteSpace trims only these four.
_CPP_SPACE = " \t\n\v\f\r"
_TRIM = " \t\n\r"
# MOOSRemoveChars(line, " \t\r"): the raw block list and GetTokenValPair.
_SQUEEZE = str.maketrans("", "", " \t\r")
# parse_log_spec removes every ASCII whitespace character (a PLOGGER_CMD string may hold \n).
_SQUEEZE_ALL = str.maketrans("", "", _CPP_SPACE)
_MOOS_NUMERIC = frozenset("1234567890.eE-+")
_INT_RE = re.compile(r"[+-]?[0-9]+")
_FLOAT_RE = re.compile(r"[+-]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][+-]?[0-9]+)?")
# The longest prefix C's strtod/atof accepts (decimal, hexadecimal, inf, nan).
_ATOF_RE = re.compile(
    r"[ \t\n\v\f\r]*(?P<num>[+-]?(?:"
    r"(?P<hex>0x(?:[0-9a-f]+\.?[0-9a-f]*|\.[0-9a-f]+)(?:p[+-]?[0-9]+)?)"
    r"|(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:e[+-]?[0-9]+)?"
    r"|inf(?:inity)?"
    r"|nan(?:\([0-9a-z_]*\))?"
    r"))",
    re.IGNORECASE,
)


# --------------------------------------------------------------------------------------------
# Small MOOS helpers


def _squeeze(text: str) -> str:
    return text.translate(_SQUEEZE)


def _key(name: str) -> str:
    """Return the form MOOSStrCmp compares: upper case."""
    return name.upper()


def _c_atof(text: str) -> float:
    """Return ``atof(text)``: the value of the longest numeric prefix, 0.0 if there is none."""
    match = _ATOF_RE.match(text)
    if match is None:
        return 0.0
    number = match.group("num")
    if match.group("hex") is not None:
        try:
            return float.fromhex(number)
        except OverflowError:
            return -math.inf if number.startswith("-") else math.inf
    lowered = number.lower()
    if "nan" in lowered:
        return math.nan
    return float(lowered)


def _is_moos_numeric(text: str) -> bool:
    """Return ``MOOSIsNumeric(text)``: trimmed, only the characters ``0-9 . e E - +``."""
    return all(char in _MOOS_NUMERIC for char in text.strip(_TRIM))


def _moos_bool(text: str) -> bool:
    """Return a MOOS boolean: ``true`` in any case, or a number greater than 0."""
    return _key(text) == "TRUE" or (_is_moos_numeric(text) and _c_atof(text) > 0)


# --------------------------------------------------------------------------------------------
# The mission file


class Param(NamedTuple):
    """One ``name = value`` line: the name and value as MOOS reads them, and where it was."""

    name: str
    value: str
    lineno: int


@dataclass(frozen=True, slots=True)
class ProcessBlock:
    """One ``ProcessConfig = NAME { … }`` block.

    Attributes:
        name: the application name as written, with blanks removed.
        lineno: the line of the ``ProcessConfig`` line.
        params: the parameters in file order, names and values trimmed at the ends (what
            MOOS's ``GetConfigurationParam`` reads); lines with an empty value are left out.
        raw: the same lines with every space, tab and CR removed from name and value (what
            MOOS's ``GetConfiguration`` list holds; used for ``Log`` and the wildcard
            patterns).
    """

    name: str
    lineno: int
    params: tuple[Param, ...] = ()
    raw: tuple[Param, ...] = ()

    def param(self, name: str) -> Param | None:
        """Return the first parameter called ``name`` (case-insensitive), or None."""
        wanted = _key(name)
        for param in self.params:
            if _key(param.name) == wanted:
                return param
        return None

    def get(self, name: str) -> str | None:
        """Return the first value of parameter ``name`` (case-insensitive), or None."""
        param = self.param(name)
        return None if param is None else param.value

    def raw_values(self, name: str) -> tuple[Param, ...]:
        """Return every raw (whitespace-free) entry whose name is ``name``, in file order."""
        wanted = _key(name)
        return tuple(param for param in self.raw if _key(param.name) == wanted)


@dataclass(frozen=True, eq=False, slots=True)
class Mission:
    """A parsed mission file.

    Attributes:
        path: the name used in error messages (the file's path, or ``<mission>``).
        text: the file's text, unchanged (what pLogger copies to ``._moos``).
        blocks: application name (as written) → its block, in file order. When two blocks
            have the same name (ignoring case), the first is kept, as MOOS's search finds it.
        file_params: every ``name = value`` line of the file, blocks included, in file
            order, with spaces, tabs and CRs removed (what MOOS's ``GetValue`` scans).
        defines: the ``define:`` names and values.
    """

    path: str
    text: str
    blocks: Mapping[str, ProcessBlock]
    file_params: tuple[Param, ...] = ()
    defines: Mapping[str, str] = field(default_factory=lambda: MappingProxyType({}))

    def global_param(self, name: str) -> Param | None:
        """Return the first file-scope ``name = value`` line for ``name``, or None."""
        wanted = _key(name)
        for param in self.file_params:
            if _key(param.name) == wanted:
                return param
        return None

    def global_value(self, name: str) -> str | None:
        """Return MOOS's file-scope value of ``name`` (case-insensitive), or None.

        The whole file is scanned, blocks included; the first match wins even if its value
        is empty, and spaces, tabs and CRs are removed from the value.
        """
        param = self.global_param(name)
        return None if param is None else param.value

    def block(self, app_name: str) -> ProcessBlock | None:
        """Return the block for ``app_name`` (case-insensitive, blanks ignored), or None."""
        wanted = _key(_squeeze(app_name))
        for name, block in self.blocks.items():
            if _key(name) == wanted:
                return block
        return None

    @property
    def community(self) -> str | None:
        """The file-scope ``Community``, or None if it is absent or empty."""
        return self.global_value("Community") or None

    def logger_config(self, app_name: str = "pLogger") -> LoggerConfig:
        """Return pLogger's configuration for the block of ``app_name``.

        See :class:`LoggerConfig` for each field, its default and where it comes from.

        Args:
            app_name: the logger's application name (``pLogger``, or ``pLogger_B`` when
                pAntler starts it as ``~ pLogger_B``).

        Returns:
            The configuration. A mission without a block for ``app_name`` gives pLogger's
            defaults with wildcard logging on (§6.4), plus the file-scope values.

        Raises:
            MissionError: a parameter pLogger reads as a number is not one, a number is out
                of range, a ``Log`` entry is invalid, or ``LogFormat`` is not ``em``/``ivp``.
        """
        return _logger_config(self, app_name)


def _clean_line(line: str) -> str | None:
    """Return a line as ``GetNextValidLine`` does before expansion, or None if it is skipped."""
    line = line.lstrip(_CPP_SPACE).strip(_TRIM)
    if not line or line.startswith("//"):
        return None
    comment = line.find("//")
    first = line.find('"')
    if first >= 0:
        second = line.find('"', first + 1)
        if second >= 0:
            line = line[:first] + line[first + 1 : second] + line[second + 1 :]
            if comment < 0 or first < comment:
                # the text after the closing quote now starts at second - 1
                comment = line.find("//", second - 1)
    if comment >= 0:
        line = line[:comment]
    return line


def _expand(
    line: str, defines: Mapping[str, str], env: Mapping[str, str], path: str, lineno: int
) -> str:
    """Expand every ``${NAME}`` in ``line`` once, from ``defines`` and else ``env``."""
    if "${" not in line:
        return line
    out: list[str] = []
    rest = line
    while (start := rest.find("${")) >= 0:
        out.append(rest[:start])
        rest = rest[start + 2 :]
        end = rest.find("}")
        if end < 0:
            msg = f"'${{' in {line!r} has no closing '}}'"
            raise MissionError(msg, path, lineno)
        name = rest[:end]
        rest = rest[end + 1 :]
        if not name:
            msg = f"'${{}}' in {line!r} names no variable"
            raise MissionError(msg, path, lineno)
        if name in defines:
            out.append(defines[name])
        elif name in env:
            out.append(env[name])
        else:
            msg = f"${{{name}}} is not defined by a 'define:' line or in the environment"
            raise MissionError(msg, path, lineno)
    out.append(rest)
    return "".join(out)


def _valid_lines(text: str) -> Iterator[tuple[int, str]]:
    for index, line in enumerate(text.split("\n")):
        cleaned = _clean_line(line)
        if cleaned is not None:
            yield index + 1, cleaned


def _read_defines(lines: list[tuple[int, str]], path: str) -> dict[str, str]:
    defines: dict[str, str] = {}
    for lineno, line in lines:
        if not line.startswith(_DEFINE):
            continue
        body = _squeeze(line[len(_DEFINE) :])
        if "=" not in body:
            msg = f"define line {line!r} has no '='"
            raise MissionError(msg, path, lineno)
        name, _, value = body.partition("=")
        if not name:
            msg = f"define line {line!r} has no name before '='"
            raise MissionError(msg, path, lineno)
        defines[name] = value
    return defines


class _OpenBlock:
    """A block being read: its ProcessConfig line, and whether its ``{`` was seen."""

    __slots__ = ("braced", "lineno", "name", "params", "raw")

    def __init__(self, name: str, lineno: int) -> None:
        self.name = name
        self.lineno = lineno
        self.braced = False
        self.params: list[Param] = []
        self.raw: list[Param] = []

    @property
    def title(self) -> str:
        return f"ProcessConfig = {self.name}"

    def close(self) -> ProcessBlock:
        return ProcessBlock(self.name, self.lineno, tuple(self.params), tuple(self.raw))


def _block_line(current: _OpenBlock, line: str, squeezed: str, path: str, lineno: int) -> None:
    """Add one line of a block's body to ``current`` (the closing ``}`` is handled before)."""
    if _key(squeezed).startswith(_PROCESS_CONFIG):
        inner = squeezed[len(_PROCESS_CONFIG) :]
        msg = (
            f"ProcessConfig = {inner} appears inside the block of {current.title} "
            f"opened on line {current.lineno}, which is not closed"
        )
        raise MissionError(msg, path, lineno)
    if line.startswith("{"):
        msg = (
            f"'{{' cannot open a block inside the block of {current.title} "
            f"opened on line {current.lineno}"
        )
        raise MissionError(msg, path, lineno)
    if "=" not in line:
        msg = f"line {line!r} in the block of {current.title} has no '='"
        raise MissionError(msg, path, lineno)
    name, _, value = line.partition("=")
    name = name.strip(_TRIM)
    value = value.strip(_TRIM)
    if not name:
        msg = f"line {line!r} in the block of {current.title} has no parameter name before '='"
        raise MissionError(msg, path, lineno)
    if not value:
        return  # MOOS ignores parameters with an empty value
    current.params.append(Param(name, value, lineno))
    current.raw.append(Param(_squeeze(name), _squeeze(value), lineno))


def parse_mission(
    text: str, path: str = "<mission>", env: Mapping[str, str] | None = None
) -> Mission:
    """Parse a MOOS mission file's text as MOOS's file readers do (§9).

    Args:
        text: the whole file.
        path: the file name for error messages and :attr:`Mission.path`.
        env: the environment for ``${NAME}`` names that no ``define:`` line gives. Pass
            ``os.environ`` to behave as MOOS does; None means an empty environment.

    Returns:
        The parsed mission.

    Raises:
        MissionError: the file cannot be read the way MOOS would read it (see the module
            docstring); the message names the file, the line and the problem.
    """
    environment: Mapping[str, str] = {} if env is None else env
    lines = list(_valid_lines(text))
    defines = _read_defines(lines, path)

    blocks: dict[str, ProcessBlock] = {}
    seen: set[str] = set()
    file_params: list[Param] = []
    current: _OpenBlock | None = None

    for lineno, cleaned in lines:
        if cleaned.startswith(_DEFINE):
            if current is not None and not current.braced:
                msg = (
                    f"{current.title} must be followed by a line beginning with '{{', "
                    f"not {cleaned!r} on line {lineno}"
                )
                raise MissionError(msg, path, current.lineno)
            continue
        line = _expand(cleaned, defines, environment, path, lineno)
        squeezed = _squeeze(line)
        if "=" in squeezed:
            name, _, value = squeezed.partition("=")
            file_params.append(Param(name, value, lineno))

        if current is not None and not current.braced:
            if not line.startswith("{"):
                msg = (
                    f"{current.title} must be followed by a line beginning with '{{', "
                    f"not {line!r} on line {lineno}"
                )
                raise MissionError(msg, path, current.lineno)
            current.braced = True
        elif current is not None:
            if squeezed.startswith("}"):
                key = _key(current.name)
                if key not in seen:
                    seen.add(key)
                    blocks[current.name] = current.close()
                current = None
            else:
                _block_line(current, line.strip(_TRIM), squeezed, path, lineno)
        elif _key(squeezed).startswith(_PROCESS_CONFIG):
            name = squeezed[len(_PROCESS_CONFIG) :]
            if "{" in name:
                msg = f"'{{' must be on its own line after ProcessConfig = {name.split('{')[0]}"
                raise MissionError(msg, path, lineno)
            if not name:
                msg = "ProcessConfig line names no application"
                raise MissionError(msg, path, lineno)
            current = _OpenBlock(name, lineno)
        elif squeezed.startswith("}"):
            msg = "'}' closes no open ProcessConfig block"
            raise MissionError(msg, path, lineno)
        elif squeezed.startswith("{"):
            msg = "'{' does not follow a ProcessConfig line"
            raise MissionError(msg, path, lineno)

    if current is not None:
        if current.braced:
            msg = f"the block of {current.title} is never closed by a line beginning with '}}'"
        else:
            msg = f"{current.title} must be followed by a line beginning with '{{', not the end"
            msg += " of the file"
        raise MissionError(msg, path, current.lineno)

    return Mission(
        path=path,
        text=text,
        blocks=MappingProxyType(blocks),
        file_params=tuple(file_params),
        defines=MappingProxyType(defines),
    )


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
        MissionError: no variable name, or a negative or non-finite period.
    """
    squeezed = text.translate(_SQUEEZE_ALL)
    var, at, rest = squeezed.partition("@")
    if not var:
        msg = f"log entry {text.strip()!r} names no variable before '@'"
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
        compress_alogs: ``CompressAlogs``: ``gzip`` → ``"gzip"`` (pLogger's ``.alog.gz``),
            ``zstd`` or any true value → ``"zstd"``, anything else → ``"none"`` (§12).
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

    def integer(self, name: str, default: int) -> int:
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
        return value

    def raw_list(self, name: str) -> tuple[str, ...]:
        if self.block is None:
            return ()
        items: list[str] = []
        for param in self.block.raw_values(name):
            items.extend(item for item in param.value.split(",") if item)
        return tuple(items)


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
    return _key(word) == "TRUE", period


def _compress_mode(reader: _Reader) -> CompressMode:
    value = reader.string("CompressAlogs", "")
    lowered = value.lower()
    if lowered == "gzip":
        return "gzip"
    if lowered == "zstd" or _moos_bool(value):
        return "zstd"
    return "none"


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
    if warp <= 0:
        msg = f"{param.name} value {param.value!r} is not greater than 0"
        raise MissionError(msg, mission.path, param.lineno)
    return warp


def _helm_task_file(mission: Mission) -> str | None:
    for app in ("pHelm", "pHelmIvP"):
        block = mission.block(app)
        if block is not None and (task_file := block.get("TaskFile")) is not None:
            return task_file
    return None


def _logger_config(mission: Mission, app_name: str) -> LoggerConfig:
    block = mission.block(app_name)
    reader = _Reader(block, mission.path)

    path = mission.global_value("GlobalLogPath") or reader.string("Path", "./")
    if path.endswith("/"):
        path = path[:-1]

    sync_log, sync_period = _sync_log(reader)
    wildcard = reader.boolean("WildcardLogging", False) if block is not None else True
    copy_dirs = tuple(
        item.strip(_TRIM)
        for param in (block.params if block is not None else ())
        if _key(param.name) == "COPYFILEDIRS"
        for item in param.value.split(",")
        if item.strip(_TRIM)
    )

    return LoggerConfig(
        app_name=app_name,
        file=reader.string("File", "MOOSLog"),
        path=path,
        file_timestamp=reader.boolean("FileTimeStamp", True),
        utc_log_directories=reader.boolean("UTCLogDirectories", False),
        async_log=wildcard or reader.boolean("AsyncLog", True),
        sync_log=sync_log,
        sync_period=sync_period,
        double_precision=reader.integer("DoublePrecision", 5),
        log_aux_src=reader.boolean("LogAuxSrc", False),
        mark_external_community_messages=reader.boolean("MarkExternalCommunityMessages", False),
        mark_data_type=reader.boolean("MarkDataType", False),
        compress_alogs=_compress_mode(reader),
        dynamic_sync_log_columns=reader.integer("DynamicSyncLogColumns", 0),
        wildcard_logging=wildcard,
        wildcard_patterns=reader.raw_list("WildcardPattern"),
        wildcard_omit_patterns=ALWAYS_OMITTED + reader.raw_list("WildcardOmitPattern"),
        wildcard_exclusion_log=reader.boolean("WildcardExclusionLog", False),
        logging_directory_summary_file=reader.string(
            "LoggingDirectorySummaryFile", ".LastOpenedMOOSLogDirectory"
        ),
        log_specs=_log_specs(reader),
        community=mission.community,
        helm_task_file=_helm_task_file(mission),
        variant=_variant(reader),
        copy_file_dirs=copy_dirs,
        moos_time_warp=_time_warp(mission),
    )
