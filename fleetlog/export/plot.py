"""Plots of a mission: variables over time, vehicles overlaid, and tracks (alogview's view).

* **Over time** (``plot VAR...``): one panel per variable, stacked on a shared time axis
  (seconds since the earliest LOGSTART among the sources, whose UTC time is in the axis
  label); one line per vehicle, the same colour for a vehicle in every panel.
* **Track** (``--xy NAV_X,NAV_Y``): y against x per vehicle, equal scales (metres on MOOS's
  local grid), a dot where each vehicle starts and a triangle where it ends. Each x is paired
  with the latest y posted at or before it, as a MOOS app would see them.

Only doubles are plotted; a variable with no double values is reported, not drawn. The
format comes from the output's suffix (``.png``, ``.svg``, ``.pdf``). matplotlib is an
optional extra (``pip install 'fleetlog[plot]'``): vehicles never need it. The figure is
made without pyplot (no global state, no display) in matplotlib's default style, so the
same data gives the same picture.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, BinaryIO

from fleetlog.errors import UsageError
from fleetlog.export.entries import Tally, entry_frames
from fleetlog.storage.columnar import Errors
from fleetlog.storage.select import Selection

if TYPE_CHECKING:
    import polars as pl

    from fleetlog.export.sources import Source

__all__ = ["FORMATS", "PlotResult", "plot", "plot_format"]

FORMATS = {".png": "png", ".svg": "svg", ".pdf": "pdf"}
_FEW = 50
_MISSING = "plots need matplotlib, an optional extra: pip install 'fleetlog[plot]'"


@dataclass
class PlotResult:
    """What was drawn.

    Attributes:
        points: points drawn per variable (all vehicles).
        missing: variables asked for that have no double values in the sources.
    """

    points: dict[str, int] = field(default_factory=dict)
    missing: list[str] = field(default_factory=list)


def plot_format(name: str) -> str:
    """The image format for an output name, from its suffix.

    Raises:
        UsageError: the suffix is not .png, .svg or .pdf.
    """
    for suffix, kind in FORMATS.items():
        if name.lower().endswith(suffix):
            return kind
    msg = f"cannot tell the image format of {name!r}: name it .png, .svg or .pdf"
    raise UsageError(msg)


def _matplotlib() -> Any:
    try:
        import matplotlib
        from matplotlib.figure import Figure
    except ImportError as err:
        raise UsageError(_MISSING) from err
    return matplotlib, Figure


def _doubles(
    sources: Sequence[Source], variables: Sequence[str], tally: Tally, errors: Errors
) -> pl.DataFrame:
    import polars as pl

    selection = Selection.of(variables, (), None, None, None)
    parts = [
        frame.filter(pl.col("type") == "double")
        .filter(pl.col("time").is_not_null())
        .select(pl.lit(source.vehicle).alias("vehicle"), "time", "variable", "double")
        for source in sources
        for frame in entry_frames(source, tally, errors=errors, selection=selection, payloads=False)
    ]
    if not parts:
        return pl.DataFrame(
            schema={
                "vehicle": pl.String,
                "time": pl.Float64,
                "variable": pl.String,
                "double": pl.Float64,
            }
        )
    return pl.concat(parts).sort("time", maintain_order=True)


def plot(
    sources: Sequence[Source],
    out: BinaryIO,
    tally: Tally,
    *,
    variables: Sequence[str] = (),
    xy: tuple[str, str] | None = None,
    image_format: str = "png",
    size: tuple[float, float] | None = None,
    dpi: int = 100,
    title: str | None = None,
    errors: Errors = "skip",
) -> PlotResult:
    """Draw the variables over time, or a track, into ``out``.

    Raises:
        UsageError: matplotlib is missing, nothing to plot was named, or nothing asked for
            holds a double value.
        StorageError: a log cannot be read or the image written.
    """
    if not variables and xy is None:
        msg = "name variables to plot, or --xy X,Y for a track"
        raise UsageError(msg)
    matplotlib, figure_class = _matplotlib()
    names = list(xy) if xy is not None else list(dict.fromkeys(variables))
    data = _doubles(sources, names, tally, errors)
    result = PlotResult()
    present = set(data["variable"].unique().to_list())
    result.missing = [n for n in names if n not in present]
    if (xy is not None and result.missing) or not present:
        msg = f"no double values of {', '.join(result.missing or names)} in the sources"
        raise UsageError(msg)
    vehicles = list(dict.fromkeys(s.vehicle for s in sources))
    with matplotlib.rc_context(matplotlib.rcParamsDefault):
        matplotlib.rcParams["svg.hashsalt"] = "fleetlog"  # stable ids in SVG output
        colours = matplotlib.rcParams["axes.prop_cycle"].by_key()["color"]
        colour = {v: colours[i % len(colours)] for i, v in enumerate(vehicles)}
        if xy is not None:
            fig = figure_class(figsize=size or (7.0, 7.0), dpi=dpi)
            _track(fig, data, xy, vehicles, colour, result)
        else:
            drawn = [n for n in names if n in present]
            fig = figure_class(figsize=size or (9.0, 1.0 + 2.0 * len(drawn)), dpi=dpi)
            starts = [s.logstart for s in sources if s.logstart is not None]
            _over_time(fig, data, drawn, vehicles, colour, min(starts), result)
        if title:
            fig.suptitle(title)
        fig.savefig(out, format=image_format, metadata=_metadata(image_format))
    return result


def _metadata(image_format: str) -> dict[str, Any]:
    # No creation date or software version in the file: the same data, the same bytes.
    if image_format == "png":
        return {"Software": None}
    if image_format == "svg":
        return {"Date": None, "Creator": None}
    return {"CreationDate": None, "Creator": None, "Producer": None}


def _over_time(
    fig: Any,
    data: pl.DataFrame,
    names: list[str],
    vehicles: list[str],
    colour: dict[str, str],
    origin: float,
    result: PlotResult,
) -> None:
    import polars as pl

    axes = fig.subplots(len(names), 1, sharex=True, squeeze=False)[:, 0]
    for ax, name in zip(axes, names, strict=True):
        rows = data.filter(pl.col("variable") == name)
        result.points[name] = rows.height
        for vehicle in vehicles:
            mine = rows.filter(pl.col("vehicle") == vehicle)
            if mine.height:
                ax.plot(
                    (mine["time"] - origin).to_list(),
                    mine["double"].to_list(),
                    color=colour[vehicle],
                    linewidth=1.0,
                    marker="." if mine.height < _FEW else None,  # a lone sample still shows
                    label=vehicle,
                )
        ax.set_ylabel(name)
        ax.grid(True, alpha=0.3)
    stamp = time.strftime("%Y-%m-%d %H:%M:%S UTC", time.gmtime(origin))
    axes[-1].set_xlabel(f"seconds since {stamp}")
    if len(vehicles) > 1:
        axes[0].legend(loc="upper right", fontsize="small")
    fig.tight_layout()


def _track(
    fig: Any,
    data: pl.DataFrame,
    xy: tuple[str, str],
    vehicles: list[str],
    colour: dict[str, str],
    result: PlotResult,
) -> None:
    import polars as pl

    ax = fig.subplots()
    x_name, y_name = xy
    for vehicle in vehicles:
        mine = data.filter(pl.col("vehicle") == vehicle)
        xs = mine.filter(pl.col("variable") == x_name).select("time", x=pl.col("double"))
        ys = mine.filter(pl.col("variable") == y_name).select("time", y=pl.col("double"))
        track = xs.join_asof(ys, on="time", strategy="backward").drop_nulls()
        result.points[vehicle] = track.height
        if not track.height:
            continue
        x, y = track["x"].to_list(), track["y"].to_list()
        ax.plot(x, y, color=colour[vehicle], linewidth=1.2, label=vehicle)
        ax.plot(x[:1], y[:1], "o", color=colour[vehicle])
        ax.plot(x[-1:], y[-1:], "^", color=colour[vehicle])
    ax.set_xlabel(f"{x_name} (m)")
    ax.set_ylabel(f"{y_name} (m)")
    ax.set_aspect("equal", adjustable="datalim")
    ax.grid(True, alpha=0.3)
    if len(vehicles) > 1:
        ax.legend(loc="best", fontsize="small")
    fig.tight_layout()
