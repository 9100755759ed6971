"""Fuzz every input a network peer or an operator controls (issue 10).

Each ``test_fuzz_<input>`` feeds cases from ``tests/hostile.py`` to the code that first
touches that input and checks the contract: no exception but fleetlog's own errors, no hang
(the watchdog in ``conftest.py``), and nothing written that reads back differently. The short
run is part of the normal suite; ``python -m pytest -m slow tests/fuzz`` runs each with
``FLEETLOG_FUZZ_CASES`` (100,000) cases. To fuzz a new reader or parser, add a target here.
"""

from __future__ import annotations

import contextlib
import math
import os
import shutil
import tempfile
from pathlib import Path
from typing import Any

from alog_oracle import AlogReader as OracleReader
from alog_oracle import classify_value, iter_entries
from fuzzer import Fuzzer
from hostile import (
    alog_files,
    attachments,
    control_requests,
    encodings,
    key_chunks,
    mission_texts,
    payloads,
    plogger_cmds,
    query_parameters,
    selector_keys,
)
from hypothesis import strategies as st

from fleetlog.errors import FleetlogError, FormatError, MissionError
from fleetlog.moos.alog import BinaryRef, source_field, split_source
from fleetlog.moos.mission import parse_mission
from fleetlog.moos.patterns import MoosGlob
from fleetlog.moos.slog_read import parse_slog
from fleetlog.moos.ylog import parse_ylog
from fleetlog.recorder.control import MAX_COPY_BYTES, MAX_LOG_REQUESTS
from fleetlog.recorder.engine import Recorder
from fleetlog.storage.alogscan import read_head
from fleetlog.storage.readers import AlogReader
from fleetlog.storage.select import Selection
from fleetlog.transport.bus import SampleDecoder
from fleetlog.wire.control import ControlRequest, Outcome, parse_control_request
from fleetlog.wire.fields import MAX_TIME, clean_name, clean_origin
from fleetlog.wire.message import Kind, MoosMessage, attachment_fields
from fleetlog.wire.query import (
    parse_file_request,
    parse_grep_request,
    parse_parameters,
    parse_service_parts,
    parse_sessions_request,
)

PREFIX = "fleet/V/var/"
T0 = 1_800_000_000.25
COMMANDS = ("PLOGGER_CMD", "LOGGER_RESTART")


def assert_safe(text: str, extra: str = "") -> None:
    """A logged field: one token for every reader, no separator of the source column."""
    assert text
    assert " " not in text
    assert not any(c in extra for c in text)
    assert all(c.isprintable() or "\udc80" <= c <= "\udcff" for c in text), repr(text)
    assert text.split() == [text]


def decoder() -> SampleDecoder:
    return SampleDecoder(PREFIX, clock=lambda: T0)


# --------------------------------------------------------------------------------------------
# Sample fields, one at a time


def check_attachment(data: bytes) -> None:
    try:
        when, source, aux, community, original = attachment_fields(data)
    except FormatError:
        pass
    else:
        assert isinstance(when, float)
        assert all(isinstance(s, str) for s in (source, aux, community))
        assert original is None or isinstance(original, float)
        s, a, c, _ = clean_origin(source, aux, community)
        if s:
            assert_safe(s, ":@")
        for field in (a, c):
            if field:
                assert_safe(field, "@")
        assert clean_origin(s, a, c) == (s, a, c, False)  # clean means clean
    incoming = decoder().decode_parts(PREFIX + "X", b"1", "text/plain;moos-double", data)
    assert incoming is not None
    msg = incoming.message
    assert 0.0 <= msg.time <= MAX_TIME
    assert msg.original_time is None or 0.0 <= msg.original_time <= MAX_TIME


def test_fuzz_attachment(fuzz: Fuzzer) -> None:
    fuzz.run(attachments, check_attachment)


def check_payload(case: tuple[bytes, str]) -> None:
    payload, encoding = case
    incoming = decoder().decode_parts(PREFIX + "X", payload, encoding, None)
    assert incoming is not None
    value = incoming.message.value
    kind = incoming.message.kind
    assert kind in (Kind.DOUBLE, Kind.STRING, Kind.BINARY)
    if isinstance(value, str):
        # no newline that would let the next line pass for an entry or a comment
        for line in value.split("\n")[1:]:
            assert not line[:1].isascii() or not (line[:1].isdigit() or line.startswith("%"))
            assert not (line.startswith("-") and line[1:2].isdigit())
    elif isinstance(value, bytes):
        assert value == payload
    else:
        assert isinstance(value, float)


def test_fuzz_payload(fuzz: Fuzzer) -> None:
    fuzz.run(st.tuples(payloads, encodings), check_payload)


def check_key(chunk: str) -> None:
    name = decoder().name_of(PREFIX + chunk)
    if name is not None:
        assert_safe(name)
        assert clean_name(name) == (name, False)


def test_fuzz_key(fuzz: Fuzzer) -> None:
    fuzz.run(key_chunks, check_key)


# --------------------------------------------------------------------------------------------
# Whole samples through the recorder, onto disk and back


class _Clock:
    def __init__(self) -> None:
        self.t = T0

    def __call__(self) -> float:
        return self.t


def _mission(mark: bool, aux: bool, external: bool) -> str:
    flags = {"MarkDataType": mark, "LogAuxSrc": aux, "MarkExternalCommunityMessages": external}
    body = "\n".join(f"  {k} = {'true' if v else 'false'}" for k, v in flags.items())
    return (
        "Community = V\nProcessConfig = pLogger\n{\n  File = F\n  WildcardLogging = true\n"
        f"{body}\n}}\n"
    )


samples = st.tuples(key_chunks, payloads, encodings, st.none() | attachments)
line_cases = st.tuples(
    st.lists(samples, min_size=1, max_size=6),
    st.booleans(),
    st.booleans(),
    st.booleans(),
    st.floats(0, 20),
)


def check_lines(case: tuple[list[Any], bool, bool, bool, float]) -> None:
    items, mark, aux, external = case[:4]
    where = Path(tempfile.mkdtemp(prefix="fleetlog-fuzz-"))
    try:
        clock = _Clock()
        cfg = parse_mission(_mission(mark, aux, external), "f.moos").logger_config()
        posted: list[MoosMessage] = []
        rec = Recorder(cfg, vehicle="V", publish=posted.append, cwd=where, clock=clock)
        session = rec.start()
        clock.t = T0 + case[4]
        dec = SampleDecoder(PREFIX, clock=clock)
        expected = []
        for chunk, payload, encoding, attachment in items:
            incoming = dec.decode_parts(PREFIX + chunk, payload, encoding, attachment)
            if incoming is None or incoming.message.name in (*COMMANDS, "MISSION_FILE"):
                continue
            msg = incoming.message
            rec.handle(msg, garbled=incoming.garbled)
            source = source_field(
                msg.source or "?",
                msg.aux,
                msg.community,
                log_aux=aux,
                mark_external=external,
                own_community="V",
            )
            expected.append((msg.name, source, msg.value))
        alog = session.dir_path / (session.root + ".alog")
        rec.stop()
        with AlogReader(alog) as reader:
            entries = list(reader.entries())
            assert not reader.truncated
            for entry, (name, source, value) in zip(entries, expected, strict=True):
                assert entry.key == name
                assert entry.source == source
                assert split_source(entry.source)[0]
                assert 0.0 <= entry.offset <= clock.t - T0 + 5.0 + 1e-5
                if isinstance(value, str) and not mark and isinstance(entry.value, float):
                    # pLogger's format cannot tell a string that looks like a padded double
                    # from a double without MarkDataType (docs/wire.md); the text survives.
                    assert entry.text == value.rstrip(" ")
                    classified = classify_value(value)[0]
                    assert isinstance(classified, float)
                    assert classified == entry.value or math.isnan(entry.value)
                elif isinstance(value, str):
                    assert entry.value == value
                elif isinstance(value, bytes):
                    assert isinstance(entry.value, BinaryRef)
                    assert reader.read_binary(entry) == value
                else:
                    assert isinstance(entry.value, float)
                    assert math.isnan(value) == math.isnan(entry.value)
        assert rec.stats.logged == len(expected)
    finally:
        shutil.rmtree(where, ignore_errors=True)


def test_fuzz_lines(fuzz: Fuzzer) -> None:
    fuzz.run(line_cases, check_lines)


# --------------------------------------------------------------------------------------------
# Queries


def check_query(case: tuple[str, str]) -> None:
    key, parameters = case
    with contextlib.suppress(FormatError):
        parse_service_parts("fleet/V/@fleetlog/" + key)
    for parse in (parse_sessions_request, parse_file_request):
        with contextlib.suppress(FormatError):
            parse(parameters)
    with contextlib.suppress(FormatError):
        parse_parameters(parameters, ["since", "limit", "var", "x"])
    try:
        grep = parse_grep_request(parameters)
    except FormatError:
        return
    long_name = "a" * 20_000
    for pattern in (*grep.variables, *grep.sources):
        MoosGlob(pattern).matches(long_name)


def test_fuzz_query(fuzz: Fuzzer) -> None:
    fuzz.run(st.tuples(selector_keys(), query_parameters()), check_query)


# --------------------------------------------------------------------------------------------
# Mission files


def check_mission(text: str) -> None:
    error: MissionError | None = None
    try:
        cfg = parse_mission(text, "m.moos").logger_config()
    except MissionError as err:
        error = err
    if error is not None:
        # one line, naming the file (and the line, where there is one)
        assert "\n" not in str(error)
        assert str(error).startswith("m.moos")
        return
    assert 0 <= cfg.double_precision <= 20
    assert 0 <= cfg.dynamic_sync_log_columns <= 1000


def test_fuzz_mission(fuzz: Fuzzer) -> None:
    fuzz.run(mission_texts(), check_mission)


# --------------------------------------------------------------------------------------------
# Log files, through every reader


def check_alog_file(case: tuple[str, bytes]) -> None:
    suffix, data = case
    where = Path(tempfile.mkdtemp(prefix="fleetlog-fuzz-"))
    try:
        path = where / ("S" + suffix)
        path.write_bytes(data)
        # the columnar reader reads what the line parser read (tests/alog_oracle.py)
        with AlogReader(path, errors="skip") as new, OracleReader(path, errors="skip") as old:
            got, want = list(new.entries()), list(old.entries())
            assert [str(e) for e in got] == [str(e) for e in want]
            assert new.skipped == old.skipped
        # a grep's selective read (the literal of its glob: the first variable read) keeps
        # what the whole read keeps, and counts the same
        selection = Selection([(got[0].key if got else "NAV_X")[:4] + "*"])
        with AlogReader(path, errors="skip") as fast, AlogReader(path, errors="skip") as whole:
            kept = [str(e) for e in fast.entries(where=selection)]
            assert kept == [str(e) for e in whole.entries(where=lambda h: selection(h))]
            assert (fast.scanned, fast.skipped) == (whole.scanned, whole.skipped)
        for errors in ("skip", "raise"):
            try:
                with AlogReader(path, errors=errors) as reader:
                    for entry in reader.entries():
                        assert math.isfinite(entry.offset) or entry.offset != entry.offset
                    if reader.logstart is not None:
                        for _ in reader.records():
                            pass
            except FleetlogError:
                assert errors == "raise"
        with contextlib.suppress(FleetlogError):
            read_head(path)
        text = data.decode("utf-8", "surrogateescape")
        list(iter_entries(text.split("\n")))
        for parse in (parse_slog, parse_ylog):
            with contextlib.suppress(FormatError):
                parse(text, str(path))
    finally:
        shutil.rmtree(where, ignore_errors=True)


def test_fuzz_alog_file(fuzz: Fuzzer) -> None:
    fuzz.run(alog_files(), check_alog_file)


# --------------------------------------------------------------------------------------------
# Commands: PLOGGER_CMD strings and control requests, against one long-lived recorder


class _CommandRig:
    """A recorder whose mission directory holds secrets, FIFOs and links out, reused by every
    case of a run (so the caps on what a peer can add are reached, as in a flood)."""

    def __init__(self) -> None:
        self.where = Path(tempfile.mkdtemp(prefix="fleetlog-fuzz-"))
        mission = self.where / "mission"
        (mission / ".ssh").mkdir(parents=True)
        (mission / ".ssh" / "id_rsa").write_text("SECRET\n")
        (mission / ".hidden").write_text("SECRET\n")
        (mission / "sub" / ".hidden").mkdir(parents=True)
        (mission / "sub" / ".hidden" / "x").write_text("SECRET\n")
        (mission / "m.moos").write_text("// mission\n")
        os.mkfifo(mission / "fifo")
        (mission / "link_out").symlink_to("/etc/passwd")
        (mission / "link_in").symlink_to(mission / "m.moos")
        with open(mission / "big.bin", "wb") as f:
            f.truncate(MAX_COPY_BYTES + 1)
        self.mission = mission
        self.clock = _Clock()
        cfg = parse_mission(
            f"ProcessConfig = pLogger\n{{\n  Path = {self.where / 'logs'}\n  SyncLog = true\n"
            "  DynamicSyncLogColumns = 3\n  Log = NAV_X @ 0\n}\n",
            "f.moos",
        ).logger_config()
        self.subscribed = 0
        self.rec = Recorder(
            cfg,
            vehicle="V",
            publish=lambda msg: None,
            cwd=mission,
            copy_dirs=[mission],
            clock=self.clock,
            subscribe=self._subscribe,
        )
        self.rec.start()

    def _subscribe(self, name: str) -> None:
        self.subscribed += 1

    def probe(self) -> None:
        """A plain sample is still logged after whatever came before (or counted paused)."""
        stats = self.rec.stats
        before = stats.logged + stats.paused
        self.rec.handle(MoosMessage("NAV_X", 1.0, self.clock.t, "iOk", "", "V"))
        assert stats.logged + stats.paused == before + 1
        assert stats.lost == 0
        assert self.subscribed <= MAX_LOG_REQUESTS

    def check_no_leak(self) -> None:
        self.rec.stop()
        for found in (self.where / "logs").rglob("*"):
            if found.is_file():
                assert b"SECRET" not in found.read_bytes(), found
        shutil.rmtree(self.where, ignore_errors=True)


def check_plogger_cmd(rig: _CommandRig, value: str | float | bytes) -> None:
    rig.clock.t += 0.01
    before = rig.rec.stats.commands
    rig.rec.handle(MoosMessage("PLOGGER_CMD", value, rig.clock.t, "iEvil", "", "V"))
    assert rig.rec.stats.commands == before + 1
    last = rig.rec.commands.recent()[-1]
    assert last["ok"] or last["why"]
    rig.probe()


def test_fuzz_plogger_cmd(fuzz: Fuzzer) -> None:
    rig = _CommandRig()
    try:
        fuzz.run(plogger_cmds(), lambda value: check_plogger_cmd(rig, value))
    finally:
        rig.check_no_leak()
    stats = rig.rec.stats
    fuzz.note(f"{stats.refused_commands:,} refused ({stats.refused_copies:,} copies)")


def check_control_request(rig: _CommandRig, case: tuple[bytes, str]) -> None:
    payload, parameters = case
    try:
        request = parse_control_request(payload, parameters)
    except FormatError:
        rig.rec.commands.refuse_request(payload[:256].decode("utf-8", "replace"), "bad request")
        return
    assert isinstance(request, ControlRequest)
    replies: list[Outcome] = []
    rig.rec.commands.submit(request, replies.append)
    while rig.rec.commands.pending:
        rig.rec.commands.run_queued()
    (reply,) = replies
    assert reply.ok or reply.why
    rig.probe()


def test_fuzz_control_request(fuzz: Fuzzer) -> None:
    rig = _CommandRig()
    try:
        fuzz.run(
            st.tuples(control_requests, st.just("") | query_parameters()),
            lambda case: check_control_request(rig, case),
        )
    finally:
        rig.check_no_leak()
