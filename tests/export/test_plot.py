"""Plots compared with golden images, and the message when matplotlib is missing.

The golden images (``tests/export/data/*.png``) were made by this code with matplotlib 3.11
and checked by eye: two vehicles' NAV_X and NAV_SPEED over time, and their tracks. They are
compared with ``matplotlib.testing.compare.compare_images`` at an RMS tolerance of
:data:`TOLERANCE` (of 255 per channel): enough for anti-aliasing differences between
matplotlib releases, far too little for a missing line, a wrong colour or a moved axis. On a
failure the image made and the difference image stay in pytest's tmp directory.

Regenerate (after checking the new pictures by eye): ``FLEETLOG_REGEN_GOLDEN=1 pytest
tests/export/test_plot.py``.
"""

from __future__ import annotations

import math
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from helpers import fleetlog_cmd
from matplotlib.testing.compare import compare_images

from fleetlog.errors import UsageError
from fleetlog.export import Tally, plot_logs, resolve
from fleetlog.moos.alog import LineFormatter, format_banner
from fleetlog.storage.outputs import atomic_output

GOLDEN = Path(__file__).parent / "data"
TOLERANCE = 2.0
LOGSTART = 1750334690.0


def fleet(tmp_path: Path) -> list[Path]:
    """Two vehicles on circles of different sizes, one minute at 2 Hz, same LOGSTART."""
    fmt = LineFormatter()
    paths = []
    for name, radius, speed in (("alpha", 30.0, 1.5), ("bravo", 18.0, 1.1)):
        session = tmp_path / name / f"LOG_{name.upper()}"
        session.mkdir(parents=True)
        path = session / f"LOG_{name.upper()}.alog"
        lines = [format_banner(f"./{path.name}", LOGSTART, "Thu Jan  1 00:00:00 1970")]
        lines.append(fmt.double(0.01, "DB_TIME", f"MOOSDB_{name}", LOGSTART))
        for i in range(120):
            t = 0.5 * i + 0.1
            angle = speed * t / radius
            x, y = radius * math.cos(angle), radius * math.sin(angle)
            lines.append(fmt.double(t, "NAV_X", "uSimMarine", round(x, 3)))
            lines.append(fmt.double(t, "NAV_Y", "uSimMarine", round(y, 3)))
            lines.append(
                fmt.double(t, "NAV_SPEED", "uSimMarine", round(speed + 0.1 * math.sin(t), 3))
            )
        path.write_text("".join(lines))
        paths.append(session)
    return paths


def draw(tmp_path: Path, name: str, **options: object) -> Path:
    out = tmp_path / name
    with atomic_output(out) as f:
        plot_logs(resolve(fleet(tmp_path)).sources, f, Tally(), **options)  # type: ignore[arg-type]
    return out


@pytest.mark.parametrize(
    ("name", "options"),
    [
        ("plot_over_time.png", {"variables": ["NAV_X", "NAV_SPEED"]}),
        ("plot_track.png", {"xy": ("NAV_X", "NAV_Y"), "size": (5.0, 5.0)}),
    ],
)
def test_plot_matches_its_golden_image(
    name: str, options: dict[str, object], tmp_path: Path
) -> None:
    made = draw(tmp_path, name, **options)
    golden = GOLDEN / name
    if os.environ.get("FLEETLOG_REGEN_GOLDEN"):
        shutil.copy(made, golden)
    assert golden.is_file(), f"{golden} is missing: regenerate it (see the module docstring)"
    assert compare_images(str(golden), str(made), tol=TOLERANCE) is None


def test_a_different_picture_fails_the_comparison(tmp_path: Path) -> None:
    # the tolerance is tight enough to see a missing variable
    made = draw(tmp_path, "x.png", variables=["NAV_X", "NAV_Y"])
    assert compare_images(str(GOLDEN / "plot_over_time.png"), str(made), tol=TOLERANCE) is not None


@pytest.mark.parametrize("suffix", [".svg", ".pdf"])
def test_other_formats_by_suffix(suffix: str, tmp_path: Path) -> None:
    made = draw(tmp_path, f"x{suffix}", variables=["NAV_X"], image_format=suffix[1:])
    head = made.read_bytes()[:200]
    assert (b"<svg" in head) if suffix == ".svg" else head.startswith(b"%PDF")


def test_nothing_to_plot_is_a_clear_error(tmp_path: Path) -> None:
    with pytest.raises(UsageError, match="no double values of NOPE"):
        draw(tmp_path, "x.png", variables=["NOPE"])


def test_missing_matplotlib_says_which_extra(tmp_path: Path) -> None:
    sessions = fleet(tmp_path)
    code = (
        "import sys; sys.modules['matplotlib'] = None; sys.argv = ['fleetlog'] + sys.argv[1:];"
        " from fleetlog.cli import main; main()"
    )
    done = subprocess.run(
        [
            sys.executable,
            "-c",
            code,
            "plot",
            str(sessions[0]),
            "NAV_X",
            "-o",
            str(tmp_path / "x.png"),
        ],
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    assert done.returncode == 1
    assert "pip install 'fleetlog[plot]'" in done.stderr
    assert "Traceback" not in done.stderr
    assert not (tmp_path / "x.png").exists()


def test_plot_cli_writes_the_image(tmp_path: Path) -> None:
    sessions = fleet(tmp_path)
    out = tmp_path / "track.png"
    done = subprocess.run(
        fleetlog_cmd("plot", *map(str, sessions), "--xy", "NAV_X,NAV_Y", "-o", str(out)),
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    assert done.returncode == 0, done.stderr
    assert out.read_bytes().startswith(b"\x89PNG")
