"""Is this host's clock synchronised? The kernel's answer, from ``adjtimex``.

Merging vehicles by absolute time means nothing on clocks that were never synchronised, so
the recorder keeps the evidence: at each session's open (its metadata's ``clock``) and in
its status. Every time daemon that disciplines the clock (chrony, ntpd, systemd-timesyncd,
ptp4l with phc2sys) tells the kernel through ``adjtimex``, which clears ``STA_UNSYNC`` and
keeps an estimated and a maximum error; a read-only ``adjtimex`` call needs no privilege
and costs a system call, so it is asked directly (no subprocess, no D-Bus).
"""

from __future__ import annotations

import ctypes
import ctypes.util
import sys
from typing import Any

__all__ = ["clock_state"]

#: adjtimex's return value for a clock not synchronised (STA_UNSYNC set)
_TIME_ERROR = 5
_STA_UNSYNC = 0x0040
_NAMES = ("TIME_OK", "TIME_INS", "TIME_DEL", "TIME_OOP", "TIME_WAIT", "TIME_ERROR")
_STATES = dict(enumerate(_NAMES))


class _Timeval(ctypes.Structure):
    _fields_ = (("tv_sec", ctypes.c_long), ("tv_usec", ctypes.c_long))


class _Timex(ctypes.Structure):
    """``struct timex`` (Linux, any word size: its fields are C longs and ints)."""

    _fields_ = (
        ("modes", ctypes.c_uint),
        ("offset", ctypes.c_long),
        ("freq", ctypes.c_long),
        ("maxerror", ctypes.c_long),
        ("esterror", ctypes.c_long),
        ("status", ctypes.c_int),
        ("constant", ctypes.c_long),
        ("precision", ctypes.c_long),
        ("tolerance", ctypes.c_long),
        ("time", _Timeval),
        ("tick", ctypes.c_long),
        ("ppsfreq", ctypes.c_long),
        ("jitter", ctypes.c_long),
        ("shift", ctypes.c_int),
        ("stabil", ctypes.c_long),
        ("jitcnt", ctypes.c_long),
        ("calcnt", ctypes.c_long),
        ("errcnt", ctypes.c_long),
        ("stbcnt", ctypes.c_long),
        ("tai", ctypes.c_int),
        ("_pad", ctypes.c_int * 11),
    )


def _adjtimex() -> Any:
    if not sys.platform.startswith("linux"):
        return None
    name = ctypes.util.find_library("c")
    try:
        libc = ctypes.CDLL(name, use_errno=True)
        func = libc.adjtimex
    except (OSError, AttributeError):
        return None
    func.argtypes = (ctypes.POINTER(_Timex),)
    func.restype = ctypes.c_int
    return func


_ADJTIMEX = _adjtimex()


def clock_state(now: float) -> dict[str, Any]:
    """Return the clock's synchronisation state, as the session metadata stores it.

    ``{"source": "adjtimex", "synchronized": bool, "state": "TIME_OK"|…, "maxerror": s,
    "esterror": s, "checked": now}``; ``synchronized`` is None where the kernel cannot be
    asked (not Linux).
    """
    if _ADJTIMEX is None:
        return {"source": None, "synchronized": None, "checked": now}
    tx = _Timex()  # modes 0: read only
    result = _ADJTIMEX(ctypes.byref(tx))
    if result < 0:
        return {"source": "adjtimex", "synchronized": None, "checked": now}
    synced = result != _TIME_ERROR and not tx.status & _STA_UNSYNC
    return {
        "source": "adjtimex",
        "synchronized": synced,
        "state": _STATES.get(result, str(result)),
        "maxerror": tx.maxerror / 1e6,
        "esterror": tx.esterror / 1e6,
        "checked": now,
    }
