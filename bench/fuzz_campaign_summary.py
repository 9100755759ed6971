"""Sum the fuzz campaign's shard reports into one table per input and commit.

A shard is one run of the ``slow`` fuzz targets with ``FLEETLOG_FUZZ_REPORT=path`` (see
``tests/fuzz/conftest.py``); its report is a Markdown table, optionally followed by
``key: value`` lines that the shard's runner appended (``commit``, ``load_start``,
``load_end``, ``pytest_exit``). Shards are summed only when they ran the same commit: a
figure never mixes cases run on different code. A shard whose runner recorded a non-zero
exit but whose report holds no row (the hang watchdog ends the process before the report is
written) counts as a failed shard, never as zero cases that passed.

    python bench/fuzz_campaign_summary.py /work/notes/fuzz2-shards/*.md
"""

from __future__ import annotations

import argparse
import re
import sys
from dataclasses import dataclass, field
from pathlib import Path

NUMBER = re.compile(r"\d[\d,]*(?:\.\d+)?")


@dataclass
class Total:
    target: str
    commit: str
    cases: int = 0
    shards: int = 0
    failures: list[str] = field(default_factory=list)
    slowest_ms: float = 0.0
    seconds: float = 0.0
    loads: list[float] = field(default_factory=list)
    notes: dict[str, list[float]] = field(default_factory=dict)

    def add_note(self, note: str) -> None:
        # notes that differ only in their numbers ("1,234 refused") are summed
        template = NUMBER.sub("{}", note)
        numbers = [float(n.replace(",", "")) for n in NUMBER.findall(note)]
        if template in self.notes:
            summed = zip(self.notes[template], numbers, strict=True)
            self.notes[template] = [a + b for a, b in summed]
        else:
            self.notes[template] = numbers


def read_report(path: Path) -> tuple[list[list[str]], dict[str, str]]:
    rows: list[list[str]] = []
    meta: dict[str, str] = {}
    for line in path.read_text(encoding="utf-8").splitlines():
        if line.startswith("|"):
            cells = [c.strip() for c in line.strip().strip("|").split("|")]
            if cells[0] not in ("input", "") and not cells[0].startswith("---"):
                rows.append(cells)
        elif ": " in line:
            key, value = line.split(": ", 1)
            meta[key.strip()] = value.strip()
    return rows, meta


def summarise(paths: list[Path]) -> dict[tuple[str, str], Total]:
    totals: dict[tuple[str, str], Total] = {}
    for path in paths:
        rows, meta = read_report(path)
        commit = meta.get("commit", "unknown")
        loads = [float(meta[k].split()[0]) for k in ("load_start", "load_end") if k in meta]
        full = [r for r in rows if r[1] == "full"]
        if not full:
            target = path.stem.rsplit("-", 1)[0]
            total = totals.setdefault((target, commit), Total(target, commit))
            total.shards += 1
            exit_status = meta.get("pytest_exit", "?")
            total.failures.append(f"{path.name}: no figures (pytest exit {exit_status})")
            continue
        for target, _run, cases, outcome, slowest, seconds, notes in full:
            total = totals.setdefault((target, commit), Total(target, commit))
            total.shards += 1
            total.cases += int(cases.replace(",", ""))
            total.slowest_ms = max(total.slowest_ms, float(slowest.split()[0]))
            total.seconds += float(seconds.split()[0])
            total.loads.extend(loads)
            if outcome != "ok":
                total.failures.append(f"{path.name}: {outcome}")
            for note in filter(None, (n.strip() for n in notes.split(";"))):
                total.add_note(note)
            if meta.get("pytest_exit", "0") != "0" and outcome == "ok":
                total.failures.append(f"{path.name}: pytest exit {meta['pytest_exit']}")
    return totals


def table(totals: dict[tuple[str, str], Total]) -> str:
    lines = [
        "| input | cases | shards | outcome | slowest case | wall time | commit | load | notes |",
        "|---|---:|---:|---|---:|---:|---|---|---|",
    ]
    for t in totals.values():
        outcome = "ok" if not t.failures else "FAILED: " + "; ".join(t.failures)
        load = f"{min(t.loads):.0f}–{max(t.loads):.0f}" if t.loads else "?"
        notes = "; ".join(
            template.format(*(f"{n:,.0f}" for n in numbers))
            for template, numbers in t.notes.items()
        )
        ms = t.slowest_ms
        slowest = f"{ms:.0f} ms" if ms < 1000 else f"{ms / 1000:.1f} s"
        lines.append(
            f"| {t.target} | {t.cases:,} | {t.shards} | {outcome} | {slowest} "
            f"| {t.seconds / 60:.1f} min | `{t.commit}` | {load} | {notes} |"
        )
    return "\n".join(lines)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("reports", nargs="+", type=Path, help="shard reports (Markdown)")
    args = parser.parse_args()
    totals = summarise(sorted(args.reports))
    print(table(totals))
    return 1 if any(t.failures for t in totals.values()) else 0


if __name__ == "__main__":
    sys.exit(main())
