"""The offline alog tools, as engines the CLI only calls: info, grep, clip, sort and merge.

Each reads through the one columnar read path (:mod:`fleetlog.storage.columnar`), streams
(memory does not grow with the log), takes plain, ``.gz`` and ``.zst`` alogs or session
directories, and writes alogs that the MOOS-IvP tools read (a banner, then entry lines
byte for byte as they were in the input). ``docs/reading.md`` says where they differ from
alogscan, aloggrep, alogclip and alogsort.
"""

from fleetlog.tools.grep import GrepResult, grep_log
from fleetlog.tools.info import LogInfo, VariableInfo, scan_log
from fleetlog.tools.inputs import LogInput, open_log
from fleetlog.tools.merge import MergeResult, merge_logs
from fleetlog.tools.sort import SortResult, sort_log

__all__ = [
    "GrepResult",
    "LogInfo",
    "LogInput",
    "MergeResult",
    "SortResult",
    "VariableInfo",
    "grep_log",
    "merge_logs",
    "open_log",
    "scan_log",
    "sort_log",
]
