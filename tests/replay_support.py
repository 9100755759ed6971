"""Replayer test support: alog sessions written byte for byte as pLogger would.

``Proc`` (a CLI subprocess) lives in helpers.py and is re-exported for the replay tests.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

from helpers import Proc

from fleetlog.moos.alog import LineFormatter, format_banner
from fleetlog.moos.blog import format_blog_record

__all__ = ["Line", "MakeSession", "Proc", "write_session"]


@dataclass(frozen=True)
class Line:
    """One entry to write: offset from LOGSTART, variable, source field, value."""

    offset: float
    key: str
    source: str
    value: float | str | bytes


MakeSession = Callable[..., Path]


def write_session(
    directory: Path,
    lines: Sequence[Line],
    *,
    logstart: float = 1_800_000_000.0,
    vehicle: str | None = "alpha",
    root: str = "LOG_ALPHA_1_1_2027_____00_00_00",
    moos_community: str | None = None,
) -> Path:
    """Write a session directory ``directory/root/`` with an alog (and blog, and ._moos).

    ``vehicle`` adds a leading ``DB_TIME`` line from ``MOOSDB_<vehicle>`` (at offset 0) so the
    vehicle can be found; ``moos_community`` writes a ``._moos`` with that Community.
    """
    session = directory / root
    session.mkdir(parents=True)
    fmt = LineFormatter()
    banner = format_banner(f"./{root}/{root}.alog", logstart, "Thu Jan  1 00:00:00 1970")
    text = [banner]
    blog = bytearray()
    all_lines = list(lines)
    if vehicle is not None:
        all_lines.insert(0, Line(0.0, "DB_TIME", f"MOOSDB_{vehicle}", str(logstart)))
    for line in all_lines:
        if isinstance(line.value, bytes):
            prefix = fmt.prefix(line.offset, line.key, line.source)
            record = format_blog_record(prefix, line.value, len(blog), f"{root}.blog")
            blog += record.data
            text.append(fmt.binary(line.offset, line.key, line.source, record.ref))
        elif isinstance(line.value, str):
            text.append(fmt.string(line.offset, line.key, line.source, line.value))
        else:
            text.append(fmt.double(line.offset, line.key, line.source, line.value))
    (session / f"{root}.alog").write_text("".join(text), encoding="utf-8", newline="\n")
    (session / f"{root}.blog").write_bytes(bytes(blog))
    if moos_community is not None:
        moos = format_banner(f"./{root}/{root}._moos", logstart, "Thu Jan  1 00:00:00 1970")
        mission = f"ServerPort = 9000\nCommunity = {moos_community}\n\n"
        (session / f"{root}._moos").write_text(moos + mission, encoding="utf-8")
    return session
