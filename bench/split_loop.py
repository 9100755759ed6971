"""The baseline of the read-path figures: a bare Python loop that splits each line in 4.

    python bench/split_loop.py FILE      # prints lines and lines/s

What ``docs/bench.md`` §9 compares ``fleetlog info``/``grep`` and the reader with, whole
process against whole process (paired runs).
"""

from __future__ import annotations

import sys
import time


def main() -> None:
    start = time.perf_counter()
    n = 0
    with open(sys.argv[1], encoding="utf-8", errors="surrogateescape") as f:
        for line in f:
            line.split(None, 3)
            n += 1
    rate = n / (time.perf_counter() - start)
    print(f"{n} lines {rate / 1e6:.2f}M lines/s")


if __name__ == "__main__":
    main()
