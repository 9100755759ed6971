"""What the export tests share: the reference logs and what the oracle says they hold."""

from __future__ import annotations

import math
import shutil
from decimal import Decimal
from pathlib import Path
from typing import NamedTuple

from alog_oracle import AlogReader as OracleReader
from helpers import REFERENCE

from fleetlog.moos.alog import BinaryRef, split_source

#: every alog of the recorded reference sessions (captured by real pLogger, and synthetic)
REFERENCE_ALOGS = sorted(
    p
    for p in REFERENCE.rglob("*")
    if p.is_file() and p.name.endswith((".alog", ".alog.gz", ".alog.zst"))
)
IVP = REFERENCE / "ivp_session/LOG_ALPHA_19_6_2025_____12_04_50"
THEMOOS = REFERENCE / "themoos_session/MOOSLog_3_2_2025_____09_05_07"
RUN_A1 = REFERENCE / "captured/runA_themoos_wildcard_restart/logs/TEST_22_11_2026_____11_06_44"
RUN_A2 = REFERENCE / "captured/runA_themoos_wildcard_restart/logs/TEST_22_11_2026_____11_06_52"


class Expected(NamedTuple):
    """One entry as the oracle (the line parser) reads it, in export terms."""

    offset: float
    time: float | None
    time_ns: int | None
    variable: str
    source: str
    aux: str
    community: str
    type: str
    double: float | None
    string: str | None
    binary: bytes | None


def expected(path: Path) -> list[Expected]:
    """The entries of an alog in file order, from the oracle, never from fleetlog's reader."""
    out = []
    with OracleReader(path, errors="skip") as reader:
        logstart = reader.logstart
        for entry in reader.entries():
            src, aux, community = split_source(entry.source)
            value = entry.value
            payload = None
            if isinstance(value, BinaryRef):
                kind, double, string = "binary", None, entry.text
                try:
                    payload = reader.read_binary(entry)
                except Exception:
                    payload = None
            elif isinstance(value, float):
                kind, double, string = "double", value, None
            else:
                kind, double, string = "string", None, value
            ns = None
            if logstart is not None:
                ns = int((Decimal(repr(logstart)) * 10**9).to_integral_value()) + round(
                    entry.offset * 1e9
                )
            out.append(
                Expected(
                    entry.offset,
                    None if logstart is None else logstart + entry.offset,
                    ns,
                    entry.key,
                    src,
                    aux,
                    community,
                    kind,
                    double,
                    string,
                    payload,
                )
            )
    return out


def same_double(a: float | None, b: float | None) -> bool:
    if a is None or b is None:
        return a is b
    if math.isnan(a):
        return math.isnan(b)
    return a == b and math.copysign(1, a) == math.copysign(1, b)


def session_dir(alog: Path) -> Path:
    return alog.parent


def copy_session(src: Path, dest: Path) -> Path:
    """Copy a session directory (real files) to ``dest`` and return it."""
    shutil.copytree(src, dest)
    return dest
