"""What collect's link-friendly pacing costs on a fast link: LinkPacer against fetch's window.

The session of ``bench/fetch_throughput.py`` (200 MB by default) served by ``fleetlog serve``
on loopback; per round, interleaved, ``fetch_session`` with the fixed window ``fetch`` uses
(8 ranges of 1 MiB: the baseline) and with the :class:`~fleetlog.shore.pacing.LinkPacer`
``collect`` uses, which starts small and grows while the round trips stay short. Each
transfer is primed as in fetch_throughput (scratch memory written and freed first).

    python bench/collect_lan.py                  # 200 MB, 5 rounds
"""

from __future__ import annotations

import argparse
import shutil
import statistics
import tempfile
import time
from pathlib import Path

from fetch_throughput import SESSION, VEHICLE, Served, loadavg, make_session, prime

from fleetlog.shore.client import FleetClient
from fleetlog.shore.fetch import fetch_session
from fleetlog.shore.pacing import FixedPacer, LinkPacer, Pacer
from fleetlog.transport.session import SessionOptions


def one(client: FleetClient, out: Path, pacer: Pacer, size: int) -> float:
    shutil.rmtree(out, ignore_errors=True)
    out.mkdir()
    prime(out, size)
    started = time.perf_counter()
    outcome = fetch_session(client, VEHICLE, SESSION, out, pacer=pacer)
    seconds = time.perf_counter() - started
    if not outcome.complete:
        raise RuntimeError(f"the fetch did not complete: {outcome}")
    return seconds


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--mb", type=int, default=200)
    parser.add_argument("--rounds", type=int, default=5)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        session = make_session(root / "logs", args.mb)
        size = sum(p.stat().st_size for p in session.iterdir())
        fixed: list[float] = []
        link: list[float] = []
        with Served(root / "logs") as endpoint:
            options = SessionOptions(connect=(endpoint,), multicast_scouting=False)
            with FleetClient.open(options) as client:
                client.require(VEHICLE)
                for _ in range(args.rounds):
                    fixed.append(one(client, root / "out", FixedPacer(), size))
                    link.append(one(client, root / "out", LinkPacer(), size))
    mb = size / 1e6
    ratios = [f / li for f, li in zip(fixed, link, strict=True)]
    print(f"{mb:.0f} MB session, {args.rounds} rounds; load {loadavg()}")
    print(f"fixed 8 x 1 MiB (fetch): {statistics.median([mb / s for s in fixed]):.0f} MB/s")
    print(f"LinkPacer (collect):     {statistics.median([mb / s for s in link]):.0f} MB/s")
    low, high = min(ratios), max(ratios)
    print(f"LinkPacer / fixed: {statistics.median(ratios):.2f} [{low:.2f}-{high:.2f}]")


if __name__ == "__main__":
    main()
