"""collect over a 1 Mbit/s radio link with 200 ms each way: a poke still answers within 1 s.

The run is ``bench/collect_link.py``'s (namespaces joined by ``tests/radio_link.py``, a real
recorder, a probe doing what ``fleetlog poke`` does every 0.5 s, then ``collect --once``),
marked slow (about a minute); its throughput against a raw TCP copy is in docs/bench.md.
"""

from __future__ import annotations

import sys
from pathlib import Path

import pytest
from query_support import same_tree
from radio_link import radio_unavailable

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "bench"))

from collect_link import SESSION, run


@pytest.mark.slow
def test_a_poke_answers_within_a_second_while_collect_fills_the_link(tmp_path: Path) -> None:
    why = radio_unavailable()
    if why is not None:
        pytest.skip(f"NO RADIO LINK HERE: {why}")
    figures = run(1.5, 1e6, 0.2, 100_000, tmp_path)
    during = figures["during_collect"]
    assert isinstance(during, list)
    assert len(during) >= 10  # the probe ran all along the transfer
    assert None not in during, figures
    assert max(during) < 1.0, figures
    same_tree(tmp_path / "logs" / SESSION, tmp_path / "archive" / "alpha" / SESSION)
