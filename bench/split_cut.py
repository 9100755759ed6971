"""How long a split holds up the recording thread, against a LOGGER_RESTART (the baseline).

Both close the open session and open the next one in the drain thread; nothing is received
meanwhile, so their duration is the stall a split adds at full rate. A real Recorder on a
real temporary directory (a slog, a mission copy; fsync and metadata in the background
writer's thread, as the service runs them), with 2,000 lines written into each session before
it is cut; rounds alternate split and restart. Prints the
median and 90th percentile wall time of each, and the ratio.

    python bench/split_cut.py --rounds 40
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

from fleetlog.moos.mission import parse_mission
from fleetlog.recorder.background import BackgroundWriter
from fleetlog.recorder.engine import Recorder
from fleetlog.wire.message import MoosMessage

MISSION = (
    "Community = bench\nProcessConfig = pLogger\n{{\n  Path = {path}\n  SyncLog = true @ 0.2\n"
    "  Log = NAV_X @ 0\n  Log = NAV_Y @ 0\n}}\n"
)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--rounds", type=int, default=40)
    parser.add_argument("--lines", type=int, default=2000)
    args = parser.parse_args()
    where = Path(tempfile.mkdtemp(prefix="fleetlog-bench-"))
    (where / "logs").mkdir()
    mission = where / "m.moos"
    mission.write_text(MISSION.format(path=where / "logs"))
    cfg = parse_mission(mission.read_text(), str(mission)).logger_config()
    clock = [time.time()]
    errors: list[str] = []
    background = BackgroundWriter(errors.append)  # fsync and metadata off the thread, as served
    rec = Recorder(
        cfg,
        vehicle="bench",
        publish=lambda msg: None,
        mission_path=mission,
        cwd=where,
        clock=lambda: clock[0],
        background=background.submit,
    )
    rec.start()
    times: dict[str, list[float]] = {"split": [], "restart": []}
    for index in range(args.rounds * 2):
        for i in range(args.lines):
            clock[0] += 0.001
            rec.handle(MoosMessage("NAV_X", float(i), clock[0], "iBench", "", "bench"))
        rec.tick()
        clock[0] += 1.0  # past the one-a-second bound on SPLIT
        kind = "split" if index % 2 == 0 else "restart"
        began = time.perf_counter()
        outcome = rec.split() if kind == "split" else rec.restart()
        times[kind].append(time.perf_counter() - began)
        assert outcome.ok, outcome.why
    rec.stop()
    background.close()
    assert not errors, errors
    for kind, found in times.items():
        found.sort()
        p90 = found[int(len(found) * 0.9)]
        print(f"{kind:8s} median {statistics.median(found) * 1e3:6.2f} ms  p90 {p90 * 1e3:6.2f} ms")
    ratio = statistics.median(times["split"]) / statistics.median(times["restart"])
    print(f"split / restart (median): {ratio:.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
