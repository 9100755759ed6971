"""Fuzz what collect and the vehicle's retention take from the network (issue 13).

* the ``prune`` control request, on either control key (the vehicle's side);
* a ``prune`` reply's list of removed sessions (the shore's side);
* vehicle names from liveliness tokens, which become archive directories;
* the acknowledgements file retention reads (written from ``ack`` requests).

Same contract as ``test_inputs.py``: fleetlog's own errors only, no hang, and what passes is
what the code after it relies on.
"""

from __future__ import annotations

import json
import tempfile
from pathlib import Path
from typing import Any

from fuzzer import Fuzzer
from hostile import payloads
from hypothesis import strategies as st

from fleetlog.errors import FormatError
from fleetlog.shore.collect_rounds import pruned_names
from fleetlog.shore.control import ControlReply
from fleetlog.storage.archive import check_vehicle_dir
from fleetlog.storage.retention import read_acks
from fleetlog.wire.control import PRUNE, check_command_key, parse_control_request
from fleetlog.wire.session_meta import ACKS_NAME

JSONISH = st.recursive(
    st.none() | st.booleans() | st.integers() | st.floats() | st.text(max_size=40),
    lambda kids: st.lists(kids, max_size=5) | st.dictionaries(st.text(max_size=10), kids),
    max_leaves=20,
)


@st.composite
def prune_requests(draw: st.DrawFn) -> tuple[bytes, bool]:
    """A request that looks like a prune (or another command), and the key it came on."""
    obj: dict[str, Any] = {"cmd": draw(st.sampled_from([PRUNE, "ack", "status", "PRUNE", ""]))}
    obj.update(draw(st.dictionaries(st.sampled_from(["session", "files", "x", "source"]), JSONISH)))
    body = json.dumps(obj).encode() if draw(st.booleans()) else draw(payloads)
    return body, draw(st.booleans())


def check_prune_request(case: tuple[bytes, bool]) -> None:
    payload, pruning = case
    try:
        request = check_command_key(parse_control_request(payload, ""), pruning=pruning)
    except FormatError as err:
        error = str(err)
    else:
        assert (request.cmd == PRUNE) == pruning
        if request.cmd == PRUNE:
            assert dict(request.args) == {}  # prune takes nothing a peer could steer
        return
    assert "\n" not in error


def test_fuzz_prune_request(fuzz: Fuzzer) -> None:
    fuzz.run(prune_requests(), check_prune_request)


def check_prune_reply(data: bytes) -> None:
    try:
        reply = ControlReply.from_json(data)
    except FormatError:
        return
    names = pruned_names(reply.extra)
    assert all(isinstance(n, str) for n in names)


def test_fuzz_prune_reply(fuzz: Fuzzer) -> None:
    crafted = st.builds(
        lambda removed, rest: json.dumps({"ok": True, "removed": removed, **rest}).encode(),
        JSONISH,
        st.dictionaries(st.text(max_size=8), JSONISH, max_size=3),
    )
    fuzz.run(crafted | payloads, check_prune_reply)


def check_vehicle_name(name: str) -> None:
    try:
        checked = check_vehicle_dir(name)
    except FormatError:
        return
    assert "/" not in checked
    assert "\x00" not in checked
    assert checked not in ("", ".", "..")
    assert not checked.startswith(".")


def test_fuzz_vehicle_name(fuzz: Fuzzer) -> None:
    fuzz.run(st.text(max_size=300) | st.sampled_from(["..", ".", "a/b", ".hidden", "x" * 300]),
             check_vehicle_name)  # fmt: skip


def check_acks(data: bytes) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        (Path(tmp) / ACKS_NAME).write_bytes(data)
        acks = read_acks(Path(tmp))
    for session, files in acks.items():
        assert isinstance(session, str)
        for name, digests in files.items():
            assert isinstance(name, str)
            assert all(isinstance(d, str) and len(d) == 64 for d in digests)


def test_fuzz_acks_file(fuzz: Fuzzer) -> None:
    line = st.builds(
        lambda obj: json.dumps(obj).encode() + b"\n",
        st.fixed_dictionaries(
            {"session": JSONISH | st.text(max_size=10), "files": JSONISH}, optional={"x": JSONISH}
        ),
    )
    fuzz.run(st.lists(line | payloads, max_size=5).map(b"".join), check_acks)
