"""A plain Zenoh client, written from docs/wire.md and docs/deploy.md alone (no fleetlog).

    python plain_client.py OPERATOR_ZENOH_JSON5 OUT_DIR

Lists the vehicles up (their recorder tokens), asks each vehicle's sessions, and fetches
every file of each vehicle's newest complete session by 1 MiB ranges, checking the sha256
the vehicle reports. Prints one JSON line per fetched file.
"""

import hashlib
import json
import sys
from pathlib import Path

import zenoh


def main(config: str, out: Path) -> None:
    conf = zenoh.Config.from_file(config)
    with zenoh.open(conf) as s:
        tokens = s.liveliness().get("fleet/*/@fleetlog/recorder", timeout=5)
        vehicles = sorted(str(r.ok.key_expr).split("/")[1] for r in tokens if r.ok is not None)
        print(json.dumps({"vehicles": vehicles}), flush=True)
        for vehicle in vehicles:
            sessions = []
            replies = s.get(
                f"fleet/{vehicle}/@fleetlog/sessions",
                timeout=30,
                consolidation=zenoh.ConsolidationMode.NONE,
            )
            for reply in replies:
                if reply.ok is not None:
                    sessions.extend(json.loads(reply.ok.payload.to_bytes())["sessions"])
            done = [x for x in sessions if x["complete"]]
            if not done:
                continue
            newest = done[-1]
            for f in newest["files"]:
                key = f"fleet/{vehicle}/@fleetlog/file/{newest['name']}/{f['name']}"
                data = b""
                while True:
                    params = f"offset={len(data)};length=1048576;sha256=1"
                    (reply,) = list(s.get(f"{key}?{params}", timeout=30))
                    meta = json.loads(reply.ok.attachment.to_bytes())
                    data += reply.ok.payload.to_bytes()
                    if len(data) >= meta["size"]:
                        break
                assert hashlib.sha256(data).hexdigest() == meta["sha256"], key
                target = out / vehicle / newest["name"] / f["name"]
                target.parent.mkdir(parents=True, exist_ok=True)
                target.write_bytes(data)
                print(
                    json.dumps(
                        {
                            "vehicle": vehicle,
                            "file": f["name"],
                            "size": len(data),
                            "sha256": meta["sha256"],
                        }
                    ),
                    flush=True,
                )


if __name__ == "__main__":
    main(sys.argv[1], Path(sys.argv[2]))
