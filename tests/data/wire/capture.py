"""Record what a vehicle of this fleetlog's wire protocol answers (run once per version).

    python tests/data/wire/capture.py v1

serves tests/data/reference/ivp_session with ``fleetlog serve`` under a private key root,
puts a recording proxy in front of it under ``fleet``, and runs the shore's commands of this
version against the proxy: fleet, sessions, fetch and query. Every query and its replies go
to tests/data/wire/<version>-alpha.jsonl, which tests/deploy/test_wire_version.py answers
from (tests/wire_compat_support.py) to check that a newer shore still works with it.
"""

from __future__ import annotations

import shutil
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import zenoh

HERE = Path(__file__).resolve().parent
TESTS = HERE.parents[1]
sys.path.insert(0, str(TESTS))

from helpers import REFERENCE, free_port  # noqa: E402
from wire_compat_support import Exchange, encode_reply  # noqa: E402


def main(version: str) -> None:
    work = Path(tempfile.mkdtemp())
    logs = work / "logs"
    shutil.copytree(REFERENCE / "ivp_session", logs)  # copy2: the files keep their times
    real, front = free_port(), free_port()
    serve = subprocess.Popen(
        [sys.executable, "-m", "fleetlog", "serve", str(logs), "--vehicle", "alpha",
         "--root", "v1real", "-l", f"tcp/127.0.0.1:{real}", "--no-multicast-scouting"],
    )  # fmt: skip
    time.sleep(3)
    conf = zenoh.Config()
    conf.insert_json5("mode", '"peer"')
    conf.insert_json5("connect/endpoints", f'["tcp/127.0.0.1:{real}"]')
    conf.insert_json5("listen/endpoints", f'["tcp/127.0.0.1:{front}"]')
    conf.insert_json5("scouting/multicast/enabled", "false")
    session = zenoh.open(conf)
    recorded: list[Exchange] = []
    lock = threading.Lock()

    def forward(query: zenoh.Query) -> None:
        key, params = str(query.key_expr), str(query.parameters)
        inner = "v1real/" + key.split("/", 1)[1]
        selector = f"{inner}?{params}" if params else inner
        payload = query.payload.to_bytes() if query.payload is not None else None
        replies = list(
            session.get(selector, payload=payload, timeout=60,
                        consolidation=zenoh.ConsolidationMode.NONE)
        )  # fmt: skip
        encoded = []
        for reply in replies:
            rep = encode_reply(reply)
            if "key" in rep:
                rep["key"] = "fleet/" + rep["key"].split("/", 1)[1]
            encoded.append(rep)
            if reply.ok is not None:
                s = reply.ok
                query.reply(rep["key"], s.payload.to_bytes(), encoding=s.encoding,
                            attachment=s.attachment)  # fmt: skip
            else:
                query.reply_err(reply.err.payload.to_bytes())
        with lock:
            recorded.append(Exchange(key, params, encoded))

    queryable = session.declare_queryable("fleet/alpha/@fleetlog/**", forward)
    token = session.liveliness().declare_token("fleet/alpha/@fleetlog/serve")
    common = ["-e", f"tcp/127.0.0.1:{front}", "--no-multicast-scouting"]
    out = work / "fetched"
    session_name = "LOG_ALPHA_19_6_2025_____12_04_50"
    for args in (
        ["fleet", "--json"],
        ["sessions", "alpha"],
        ["fetch", "alpha", session_name, "-o", str(out)],
        ["query", "alpha", "NAV_*", "--session", session_name],
        ["query", "alpha", "DEPLOY"],
    ):
        done = subprocess.run([sys.executable, "-m", "fleetlog", *args, *common],
                              capture_output=True, text=True, timeout=120)  # fmt: skip
        print(" ".join(args), "->", done.returncode, done.stderr.strip()[:200])
    token.undeclare()
    queryable.undeclare()
    session.close()
    serve.terminate()
    serve.wait(10)
    target = HERE / f"{version}-alpha.jsonl"
    target.write_text("".join(e.to_json() + "\n" for e in recorded))
    print(f"{len(recorded)} exchanges -> {target}")
    shutil.rmtree(work)


if __name__ == "__main__":
    main(sys.argv[1])
