"""Foxglove's view of a MOOS log: a value schema, and positions for the Map and 3D panels.

Every variable becomes a channel of JSON messages ``{value, source, aux, community}``
(:data:`VALUE_SCHEMA`). Where a vehicle's log has them, two more channels let Foxglove draw
it without a user script:

* ``/<vehicle>/location``, ``foxglove.LocationFix`` from NAV_LAT and NAV_LONG (the Map
  panel); ``frame_id`` is the vehicle;
* ``/<vehicle>/pose``, ``foxglove.PoseInFrame`` from NAV_X, NAV_Y and NAV_HEADING (the 3D
  panel), in frame ``map``: MOOS's local grid (x east, y north, metres), which every vehicle
  of a mission shares through its LatOrigin/LongOrigin. NAV_Z gives z where logged.
  MOOS headings are compass degrees (clockwise from north); the orientation is the yaw
  about +z from +x (east), as Foxglove expects: ``yaw = radians(90 - heading)``.

A sample is made at every time one of the inputs was posted, once all of them have been
(the latest value of each, as a MOOS app would see them). The schemas are written here from
Foxglove's message definitions (``foxglove.LocationFix``, ``foxglove.PoseInFrame``), as
JSON Schema: Foxglove recognises the schema by its name.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from typing import TYPE_CHECKING, NamedTuple

if TYPE_CHECKING:
    import polars as pl

__all__ = [
    "LOCATION_FIX",
    "LOCATION_VARS",
    "POSE_IN_FRAME",
    "POSE_VARS",
    "VALUE_SCHEMA",
    "Derived",
    "locations",
    "poses",
]

#: The variables the derived channels read.
LOCATION_VARS = ("NAV_LAT", "NAV_LONG")
POSE_VARS = ("NAV_X", "NAV_Y", "NAV_HEADING")
NAV_VARS = frozenset((*LOCATION_VARS, *POSE_VARS, "NAV_Z"))
POSE_FRAME = "map"

VALUE_SCHEMA: dict[str, object] = {
    "title": "fleetlog.MoosValue",
    "description": "One MOOS variable's value as the logger recorded it",
    "type": "object",
    "properties": {
        "value": {
            "type": ["number", "string", "null"],
            "description": "A double (null for NaN and infinities), a string, or a binary"
            " value's bytes in base64",
        },
        "source": {"type": "string", "description": "The process that posted it"},
        "aux": {"type": "string", "description": "Its aux source (empty without one)"},
        "community": {"type": "string", "description": "Its community if marked (@...)"},
    },
}

_TIME = {
    "type": "object",
    "title": "time",
    "properties": {"sec": {"type": "integer"}, "nsec": {"type": "integer"}},
}
_VECTOR = {
    "type": "object",
    "properties": {k: {"type": "number"} for k in ("x", "y", "z")},
}
LOCATION_FIX: dict[str, object] = {
    "title": "foxglove.LocationFix",
    "description": "A navigation satellite fix for any Global Navigation Satellite System",
    "type": "object",
    "properties": {
        "timestamp": _TIME,
        "frame_id": {"type": "string"},
        "latitude": {"type": "number", "description": "Latitude in degrees"},
        "longitude": {"type": "number", "description": "Longitude in degrees"},
        "altitude": {"type": "number", "description": "Altitude in meters"},
        "position_covariance": {
            "type": "array",
            "items": {"type": "number"},
            "minItems": 9,
            "maxItems": 9,
        },
        "position_covariance_type": {
            "type": "integer",
            "oneOf": [
                {"title": name, "const": i}
                for i, name in enumerate(("UNKNOWN", "APPROXIMATED", "DIAGONAL_KNOWN", "KNOWN"))
            ],
        },
    },
}
POSE_IN_FRAME: dict[str, object] = {
    "title": "foxglove.PoseInFrame",
    "description": "A timestamped pose for an object or reference frame in 3D space",
    "type": "object",
    "properties": {
        "timestamp": _TIME,
        "frame_id": {"type": "string"},
        "pose": {
            "type": "object",
            "properties": {
                "position": _VECTOR,
                "orientation": {
                    "type": "object",
                    "properties": {k: {"type": "number"} for k in ("x", "y", "z", "w")},
                },
            },
        },
    },
}


class Derived(NamedTuple):
    """A derived channel's messages: one row each, and the expression of their JSON text.

    ``rows`` has ``log_time`` and the inputs; ``data`` evaluated on them gives the text (so
    the caller can have it made where and in what slices it likes).
    """

    rows: pl.DataFrame
    data: pl.Expr

    def frame(self) -> pl.DataFrame:
        """``log_time`` and ``data``, made now."""
        return self.rows.select("log_time", data=self.data)


def schema_bytes(schema: Mapping[str, object]) -> bytes:
    """A schema as the bytes an MCAP Schema record holds."""
    return json.dumps(schema, separators=(",", ":")).encode()


def _wide(
    nav: pl.DataFrame, needed: tuple[str, ...], optional: tuple[str, ...]
) -> tuple[pl.DataFrame, set[str]]:
    """One row per time any of the variables was posted, with the latest of each.

    Also the variables that were posted (an optional one that was not is 0.0 throughout).
    """
    import polars as pl

    wanted = [*needed, *optional]
    rows = nav.filter(pl.col("variable").is_in(wanted))
    present = set(rows["variable"].unique().to_list())
    if not set(needed) <= present:
        return pl.DataFrame(), present
    if not rows["log_time"].is_sorted():
        rows = rows.sort("log_time", maintain_order=True)  # file order among equal times
    # Each row carries the latest value of every variable so far (a forward fill); the last
    # row of a time then has the last value posted at it, or the latest before. (A pivot
    # did the same at three times the cost.)
    wide = (
        rows.select(
            "log_time",
            *(
                pl.when(pl.col("variable") == name).then(pl.col("double")).alias(name)
                for name in wanted
                if name in present
            ),
        )
        .with_columns(pl.exclude("log_time").forward_fill())
        # the last row of each time (the rows are in time order: no hashing needed)
        .filter(pl.col("log_time").ne_missing(pl.col("log_time").shift(-1)))
    )
    for name in optional:
        if name not in wide.columns:
            wide = wide.with_columns(pl.lit(0.0).alias(name))
    wide = wide.drop_nulls(list(needed))
    if optional:
        wide = wide.with_columns(pl.col(list(optional)).fill_null(0.0))
    return wide, present


def _finite(wide: pl.DataFrame, *names: str) -> bool:
    """Whether every value of these columns is finite (then no null is written for one)."""
    return all(bool(wide[name].is_finite().all()) for name in names)


def _num(name: str | pl.Expr, *, finite: bool = False) -> pl.Expr:
    """A double as JSON text: what ``json_encode`` writes (shortest form; null unless finite).

    ``finite``: the values are known to be finite, so the text is the cast alone.
    """
    import polars as pl

    value = pl.col(name) if isinstance(name, str) else name
    if finite:
        return value.cast(pl.String)
    return pl.when(value.is_finite()).then(value.cast(pl.String)).otherwise(pl.lit("null"))


def _text(value: str) -> str:
    """A string as JSON text, exactly as polars' ``json_encode`` writes it."""
    import polars as pl

    encoded: str = pl.select(pl.struct(pl.lit(value).alias("v")).struct.json_encode()).item()
    return encoded[len('{"v":') : -1]


def _stamp() -> list[pl.Expr | str]:
    """``"timestamp":{"sec":…,"nsec":…}`` of the row's log time, as JSON text pieces."""
    import polars as pl

    return [
        '"timestamp":{"sec":',
        (pl.col("log_time") // 1_000_000_000).cast(pl.String),
        ',"nsec":',
        (pl.col("log_time") % 1_000_000_000).cast(pl.String),
        "}",
    ]


def _json(pieces: list[pl.Expr | str]) -> pl.Expr:
    """One JSON text per row from literal pieces and expressions, in one string kernel.

    Written as text rather than by ``struct.json_encode`` (3-4x its speed here); the bytes
    are the same, which tests/export/test_mcap.py checks against ``json_encode`` itself.
    """
    import polars as pl

    return pl.concat_str([pl.lit(p) if isinstance(p, str) else p for p in pieces])


def locations(nav: pl.DataFrame, vehicle: str) -> Derived:
    """``foxglove.LocationFix`` messages from NAV_LAT/NAV_LONG."""
    wide, _ = _wide(nav, LOCATION_VARS, ())
    finite = _finite(wide, *LOCATION_VARS) if wide.height else False
    return Derived(
        wide,
        _json(
            [
                "{",
                *_stamp(),
                f',"frame_id":{_text(vehicle)},"latitude":',
                _num("NAV_LAT", finite=finite),
                ',"longitude":',
                _num("NAV_LONG", finite=finite),
                ',"altitude":0.0,"position_covariance":[' + ",".join(["0.0"] * 9) + "]"
                ',"position_covariance_type":0}',
            ]
        ),
    )


def poses(nav: pl.DataFrame) -> Derived:
    """``foxglove.PoseInFrame`` messages from NAV_X/Y/HEADING (and NAV_Z)."""
    import polars as pl

    wide, present = _wide(nav, POSE_VARS, ("NAV_Z",))
    # Known finite columns need no null test; a NAV_Z never posted is 0.0 in every message.
    finite = {name: wide.height > 0 and _finite(wide, name) for name in (*POSE_VARS, "NAV_Z")}
    z: pl.Expr | str = _num("NAV_Z", finite=finite["NAV_Z"]) if "NAV_Z" in present else "0.0"
    half_yaw = (90.0 - pl.col("NAV_HEADING")) * (math.pi / 360.0)
    return Derived(
        wide,
        _json(
            [
                "{",
                *_stamp(),
                f',"frame_id":{_text(POSE_FRAME)},"pose":{{"position":{{"x":',
                _num("NAV_X", finite=finite["NAV_X"]),
                ',"y":',
                _num("NAV_Y", finite=finite["NAV_Y"]),
                ',"z":',
                z,
                '},"orientation":{"x":0.0,"y":0.0,"z":',
                # (the sine and cosine of a finite angle are finite)
                _num(half_yaw.sin(), finite=finite["NAV_HEADING"]),
                ',"w":',
                _num(half_yaw.cos(), finite=finite["NAV_HEADING"]),
                "}}}",
            ]
        ),
    )
