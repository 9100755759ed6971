"""Control requests and replies (docs/wire.md, "Control"): checked before anything runs."""

from __future__ import annotations

import contextlib
import json

import pytest
from hypothesis import given
from hypothesis import strategies as st

from fleetlog.errors import FormatError
from fleetlog.wire.control import (
    MAX_REQUEST,
    CommandRecord,
    ControlRequest,
    Outcome,
    parse_control_request,
)

DIGEST = "ab" * 32


def req(obj: object) -> ControlRequest:
    return parse_control_request(json.dumps(obj).encode(), "")


def test_json_requests_carry_their_arguments_source_and_time() -> None:
    r = req({"cmd": "note", "key": "site", "value": "bay", "source": "ops", "time": 12.5})
    assert (r.cmd, dict(r.args), r.source, r.time) == (
        "note",
        {"key": "site", "value": "bay"},
        "ops",
        12.5,
    )
    assert json.loads(r.text) == {
        "cmd": "note",
        "key": "site",
        "value": "bay",
        "source": "ops",
        "time": 12.5,
    }
    assert req({"cmd": "restart"}).args == {}
    ack = req({"cmd": "ack", "session": "S1", "files": {"S1.alog": DIGEST}})
    assert ack.args == {"session": "S1", "files": {"S1.alog": DIGEST}}


def test_hand_typed_parameters_are_the_same_request() -> None:
    r = parse_control_request(None, "cmd=note;key=site;value=bay%3Bdock;time=3")
    assert (r.cmd, dict(r.args), r.time) == ("note", {"key": "site", "value": "bay;dock"}, 3.0)
    assert parse_control_request(b"", "cmd=status").cmd == "status"


@pytest.mark.parametrize(
    ("payload", "params", "message"),
    [
        (b"", "", "names no command"),
        (b"[1]", "", "not a JSON object"),
        (b"{nope", "", "not JSON"),
        (b'{"cmd": "frobnicate"}', "", "unknown command 'frobnicate'"),
        (b'{"cmd": 3}', "", "names no command"),
        (b'{"cmd": "note", "key": "a"}', "", "command 'note' needs 'value'"),
        (b'{"cmd": "note", "key": "a", "value": 1}', "", "argument 'value' is not a string"),
        (b'{"cmd": "restart", "force": true}', "", "takes no argument 'force'"),
        (b'{"cmd": "note", "key": "k", "value": "a\\u0000b"}', "", "holds a NUL"),
        (b'{"cmd": "note", "key": "' + b"k" * 65 + b'", "value": ""}', "", "at most 64"),
        (b'{"cmd": "status"}', "cmd=status", "not both"),
        (b"", "cmd=status;bogus=1", "unknown parameter 'bogus'"),
        (b"", "cmd=status;time=soon", "'time' is not a number"),
        (b'{"cmd": "ack", "session": "..", "files": {"a": "' + b"0" * 64 + b'"}}', "", "relative"),
        (b'{"cmd": "ack", "session": "S", "files": {}}', "", "non-empty object"),
        (b'{"cmd": "ack", "session": "S", "files": {"a/b": "' + b"0" * 64 + b'"}}', "", "'/'"),
        (b'{"cmd": "ack", "session": "S", "files": {"a": "ABC"}}', "", "64 lowercase hex"),
        (b'{"cmd": "status", "source": 7}', "", "'source' is not a string"),
    ],
)
def test_malformed_requests_are_refused_naming_what_is_wrong(
    payload: bytes, params: str, message: str
) -> None:
    with pytest.raises(FormatError, match=message):
        parse_control_request(payload, params)


def test_oversized_requests_are_refused_before_they_are_parsed() -> None:
    big = json.dumps({"cmd": "note", "key": "k", "value": "x" * MAX_REQUEST}).encode()
    with pytest.raises(FormatError, match="bytes long; at most 65536"):
        parse_control_request(big, "")
    with pytest.raises(FormatError, match="at most"):
        parse_control_request(None, "cmd=note;value=" + "x" * MAX_REQUEST)
    deep = b"[" * 100_000 + b"]" * 100_000
    with pytest.raises(FormatError):
        parse_control_request(deep[:MAX_REQUEST], "")


def test_a_non_finite_time_is_not_the_command_time() -> None:
    assert parse_control_request(b'{"cmd": "status", "time": NaN}', "").time is None


@given(st.binary(max_size=2048), st.text(max_size=256))
def test_any_payload_or_parameters_give_a_request_or_a_format_error(
    payload: bytes, params: str
) -> None:
    try:
        r = parse_control_request(payload, params)
    except FormatError:
        return
    assert isinstance(r, ControlRequest)
    assert len(r.text) <= 256


@given(
    st.dictionaries(
        st.sampled_from(["cmd", "key", "value", "spec", "path", "session", "files", "x"]),
        st.one_of(
            st.text(max_size=80), st.integers(), st.none(), st.dictionaries(st.text(), st.text())
        ),
    )
)
def test_any_json_object_gives_a_request_or_a_format_error(obj: dict[str, object]) -> None:
    with contextlib.suppress(FormatError):
        parse_control_request(json.dumps(obj).encode(), "")


def test_outcome_replies_and_ring_records() -> None:
    done = Outcome.done("restart", "started session S", session="S")
    assert json.loads(done.reply()) == {
        "ok": True,
        "cmd": "restart",
        "did": "started session S",
        "why": None,
        "session": "S",
    }
    refused = Outcome.refused("pause", "not yet")
    assert json.loads(refused.reply()) == {"ok": False, "cmd": "pause", "did": "", "why": "not yet"}
    record = CommandRecord.of(refused, time=1.5, via="control", source="ops", text="t" * 300)
    assert len(record.text) == 256
    assert record.text.endswith("…")
    assert CommandRecord.from_json(record.as_json()) == record
    with pytest.raises(FormatError):
        CommandRecord.from_json({"time": "x"})
