"""Reading session logs back: the one read path, in one place to import it from.

* :class:`~fleetlog.storage.columnar.AlogReader` reads an alog (plain, gzip, zstd, cut or
  whole) as batches of typed columns, or as :class:`~fleetlog.moos.alog.Entry` objects, and
  resolves binary values against the ``.blog``;
* :func:`~fleetlog.storage.decompress.open_text` streams any log file as text;
* :func:`~fleetlog.storage.ordering.sorted_window` and
  :func:`~fleetlog.storage.ordering.merge_records` put records of one or several vehicles in
  time order without loading them;
* :func:`~fleetlog.storage.columnar.find_alog` finds a session directory's alog.
"""

from __future__ import annotations

from fleetlog.storage.columnar import SCHEMA, AlogReader, Errors, find_alog, limit_threads
from fleetlog.storage.decompress import LogBytes, LogText, open_bytes, open_text
from fleetlog.storage.ordering import (
    IndexedRecord,
    Record,
    RecordMerge,
    SortedWindow,
    merge_records,
    sorted_window,
)

__all__ = [
    "SCHEMA",
    "AlogReader",
    "Errors",
    "IndexedRecord",
    "LogBytes",
    "LogText",
    "Record",
    "RecordMerge",
    "SortedWindow",
    "find_alog",
    "limit_threads",
    "merge_records",
    "open_bytes",
    "open_text",
    "sorted_window",
]
