"""collect over a 1 Mbit/s radio link with 200 ms each way: a poke still answers within 1 s.

The run is ``bench/collect_link.py``'s: namespaces joined by the radio of
``fleetlog/deploy/netlink.py``, a real recorder, a probe doing what ``fleetlog poke`` does
every 0.5 s, then ``collect --once``. Marked slow (about a minute); its throughput against a
raw TCP copy is in docs/bench.md.
"""

from __future__ import annotations

import os
import sys
import time
from pathlib import Path

import pytest
from query_support import make_session, same_tree

from fleetlog.deploy.netlink import LinkShape, Namespace, RadioLink, namespaces_possible

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "bench"))

from collect_link import SESSION, SHORE_ADDR, VEHICLE_ADDR, Lines, fleetlog, netns, run


@pytest.mark.slow
def test_a_poke_answers_within_a_second_while_collect_fills_the_link(tmp_path: Path) -> None:
    why = namespaces_possible()
    if why is not None:
        pytest.skip(f"NO RADIO LINK HERE: {why}")
    figures = run(1.5, 1e6, 0.2, 0.8, tmp_path)
    during = figures["during_collect"]
    assert isinstance(during, list)
    assert len(during) >= 10  # the probe ran all along the transfer
    assert None not in during, figures
    assert max(during) < 1.0, figures
    same_tree(tmp_path / "logs" / SESSION, tmp_path / "archive" / "alpha" / SESSION)


@pytest.mark.slow
def test_a_link_cut_longer_than_zenoh_s_lease_mid_file(tmp_path: Path) -> None:
    """The link is cut for 15 s (past Zenoh's 10 s lease) with the alog half here."""
    why = namespaces_possible()
    if why is not None:
        pytest.skip(f"NO RADIO LINK HERE: {why}")
    tag = f"{os.getpid() % 10000}"
    vehicle, shore = Namespace(f"ccv{tag}"), Namespace(f"ccs{tag}")
    vehicle_ns, shore_ns = vehicle.name, shore.name
    shape = LinkShape(delay=0.2, rate=1e6, queue=0.8)
    link = RadioLink(vehicle, VEHICLE_ADDR, shore, SHORE_ADDR, shape)
    started: list[Lines] = []
    try:
        logs = tmp_path / "logs"
        session = make_session(logs, SESSION, 1.0)
        endpoint = f"tcp/{VEHICLE_ADDR}:7447"
        record = fleetlog("record", "--vehicle", "alpha", "-l", endpoint, "--no-multicast-scouting")
        recorder = Lines(netns(vehicle_ns, record), logs)
        started.append(recorder)
        recorder.wait_for("recording")
        archive = tmp_path / "archive"
        collect = Lines(netns(shore_ns, fleetlog("collect", str(archive), "--retry-for", "60",
                                                 "-e", endpoint, "--no-multicast-scouting")),
                        tmp_path)  # fmt: skip
        started.append(collect)
        part = archive / "alpha" / SESSION / f"{SESSION}.alog.part"
        alog = (session / f"{SESSION}.alog").stat().st_size
        deadline = time.monotonic() + 120
        while not (part.exists() and part.stat().st_size > alog // 3):
            assert time.monotonic() < deadline, collect.lines[-10:]
            time.sleep(0.1)
        link.cut()
        time.sleep(15.0)
        link.restore()
        collect.wait_for(f"{SESSION} complete", timeout=180)
        same_tree(session, archive / "alpha" / SESSION)
        assert any("link is down" in line for _, line in collect.lines)  # the lease ran out
    finally:
        for proc in reversed(started):
            proc.stop()
        link.close()
        vehicle.close()
        shore.close()
