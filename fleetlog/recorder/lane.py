"""The recorder's fast lane: a common sample formatted straight into its alog line.

Most samples a vehicle records are doubles and short strings with the usual attachment
(time, source, aux, community) on a variable that is logged to the alog as it comes. For
those, the lane reads the sample's parts and writes the whole line with one ``%`` operation
whose name and source columns were built once per key and publisher: no ``MoosMessage``, no
``Incoming`` and no call into the engine per sample.

Any other sample goes the general way (:meth:`SampleDecoder.decode`, :meth:`Recorder.handle`),
which is the specification: another encoding, no attachment or one that is malformed, escaped
or carries a replay time, a time out of range or skewed, a NaN, a payload that is not a
number or not UTF-8, a string with a newline, a variable that is throttled, excluded,
ignored, a command, a system variable or of another type than its first value, a key whose
name was escaped, and every sample while the recorder is paused, in snapshot mode, without a
session or writing a slog. The lane writes the same bytes and counts the same
(``tests/recorder/test_lane.py``, and the ``lane`` fuzz target compares both ways on
hostile samples).
"""

from __future__ import annotations

import struct
from collections.abc import Callable
from typing import Any

from fleetlog.moos.patterns import NAMES_CACHED
from fleetlog.recorder.intake import Intake
from fleetlog.recorder.snapshot_mode import SKEW_TOLERANCE
from fleetlog.transport.bus import DOUBLE_ENCODING, STRING_ENCODING, SampleDecoder
from fleetlog.wire.fields import MAX_TIME

__all__ = ["Lane"]

_unpack_time = struct.Struct("<d").unpack_from
#: a tail whose formats were never looked for
_UNKNOWN: Any = object()
#: bounds on the caches against floods of keys or publishers: keys, origins per key, and
#: line formats in all (about 2 MB at most)
_MAX_KEYS = NAMES_CACHED
_MAX_TAILS = 64
_MAX_FORMATS = 2 * NAMES_CACHED


class _Plan:
    """One key's way through the lane: its variable's name and line formats per origin."""

    __slots__ = ("formats", "name")

    def __init__(self, name: str | None) -> None:
        #: the variable's name, None when the key's samples always go the general way
        self.name = name
        #: the (double, string) line formats per attachment tail (``attachment[8:]``: source,
        #: aux, community), None for a tail whose samples go the general way
        self.formats: dict[bytes, tuple[str, str] | None] = {}


class Lane:
    """Logs samples for one drain thread: the common ones fast, the others the general way.

    Args:
        recorder: the recorder the samples go to.
        decoder: the general way's decoder (the lane shares its caches of checked names and
            origins).
        seen: sample-miss detection, given each sample that has a source info.
    """

    def __init__(
        self, recorder: Intake, decoder: SampleDecoder, seen: Callable[[Any, Any], None]
    ) -> None:
        self._recorder = recorder
        self._decoder = decoder
        self._seen = seen
        self._plans: dict[str, _Plan] = {}
        #: the origins' entries in all the plans (bounded by _MAX_FORMATS)
        self.cached = 0
        #: samples the lane logged itself (tests, benchmarks)
        self.fast = 0

    def _plan(self, key: str) -> _Plan:
        plans = self._plans
        if len(plans) >= _MAX_KEYS:
            plans.clear()
            self.cached = 0
        plan = plans[key] = _Plan(self._decoder.plain_name(key))
        return plan

    def _formats(self, plan: _Plan, attachment: bytes, tail: bytes) -> tuple[str, str] | None:
        formats = plan.formats
        if len(formats) >= _MAX_TAILS:
            self.cached -= len(formats)
            formats.clear()
        if self.cached >= _MAX_FORMATS:
            # A flood of keys and origins: start again (rare; each entry is rebuilt on use).
            for each in self._plans.values():
                each.formats.clear()
            formats.clear()
            self.cached = 0
        origin = self._decoder.plain_origin(attachment)
        name = plan.name
        found = None
        if origin is not None and name is not None:
            found = self._recorder.lane_formats(name, *origin)
        formats[tail] = found
        self.cached += 1
        return found

    def _general(self, sample: Any) -> None:
        incoming = self._decoder.decode(sample)
        if incoming is not None:
            self._recorder.handle(incoming.message, garbled=incoming.garbled)
        else:
            self._recorder.unreadable(str(sample.key_expr))

    def pump(self, sample: Any, try_recv: Callable[[], Any], budget: int) -> int:
        """Log ``sample`` and what ``try_recv`` yields next, ``budget`` at most; return how many.

        Fewer than ``budget`` means that ``try_recv`` returned None (the FIFO is empty).
        """
        recorder = self._recorder
        seen = self._seen
        plans = self._plans
        target = recorder.lane_open()
        if target is not None:
            write, vars_get, logstart, clock = target
        count = fast = 0
        first = 0.0
        while True:
            count += 1
            info = sample.source_info
            if info is not None:
                seen(info, sample)
            # The plain case of Recorder.handle, step by step; any step that is not plain
            # leaves ``line`` empty and the sample goes the general way.
            line = ""
            if target is not None:
                key = str(sample.key_expr)
                plan = plans.get(key) or self._plan(key)
                name = plan.name
                attachment = sample.attachment
                if name is not None and attachment is not None:
                    encoding = sample.encoding
                    double = encoding == DOUBLE_ENCODING
                    data = attachment.to_bytes()
                    tail = data[8:]
                    formats = plan.formats.get(tail, _UNKNOWN)
                    if formats is _UNKNOWN:
                        formats = self._formats(plan, data, tail)
                    var = vars_get(name)
                    # A cached tail means a readable attachment of 11 bytes or more.
                    if formats is not None and var is not None and var.plain:
                        (when,) = _unpack_time(data)
                        now = clock()
                        # time_ok, then the skew rule (recorder/intake.py): NaN fails both
                        if (
                            0.0 <= when <= MAX_TIME
                            and when >= logstart
                            and when - now <= SKEW_TOLERANCE
                        ):
                            if double:
                                if var.kind is float:
                                    try:
                                        value = float(sample.payload.to_bytes())
                                    except ValueError:
                                        value = float("nan")
                                    if value == value:
                                        line = formats[0] % (when - logstart, value)
                            elif var.kind is str and encoding == STRING_ENCODING:
                                try:
                                    text = sample.payload.to_bytes().decode("utf-8")
                                except UnicodeDecodeError:
                                    text = "\n"
                                if "\n" not in text:
                                    line = formats[1] % (when - logstart, text)
                            if line:
                                write(line)
                                var.last_seen = now
                                if not fast:
                                    first = now
                                fast += 1
            if not line:
                if fast:
                    # Counted before the general sample: a command there may open a session.
                    recorder.lane_logged(fast, first)
                    self.fast += fast
                    fast = 0
                self._general(sample)
                target = recorder.lane_open()
                if target is not None:
                    write, vars_get, logstart, clock = target
            if count >= budget:
                break
            sample = try_recv()
            if sample is None:
                break
        if fast:
            recorder.lane_logged(fast, first)
            self.fast += fast
        return count
