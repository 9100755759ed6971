r"""MOOS ``.moos`` mission files (MOOS_FORMAT.md §9).

Pure code: :func:`parse_mission` takes the file's text (it never opens a file) and returns a
:class:`Mission`; :meth:`Mission.logger_config` turns the pLogger block into a
:class:`LoggerConfig` (:mod:`fleetlog.moos.logger_config`, which also holds
:func:`parse_log_spec`; both are re-exported here).

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

from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import NamedTuple

from fleetlog.errors import MissionError
from fleetlog.moos.logger_config import (
    ALWAYS_LOGGED,
    ALWAYS_OMITTED,
    DEFAULT_LOG_PERIOD,
    MIN_SYNC_PERIOD,
    CompressMode,
    LoggerConfig,
    LogSpec,
    VariantName,
    logger_config,
    parse_log_spec,
)
from fleetlog.moos.settings import CPP_SPACE as _CPP_SPACE
from fleetlog.moos.settings import TRIM as _TRIM
from fleetlog.moos.settings import key as _key
from fleetlog.moos.settings import squeeze as _squeeze

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

_PROCESS_CONFIG = "PROCESSCONFIG="
_DEFINE = "define:"

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
        return logger_config(self, app_name)


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
