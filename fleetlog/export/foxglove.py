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
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    import polars as pl

__all__ = [
    "LOCATION_FIX",
    "LOCATION_VARS",
    "POSE_IN_FRAME",
    "POSE_VARS",
    "VALUE_SCHEMA",
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


def schema_bytes(schema: Mapping[str, object]) -> bytes:
    """A schema as the bytes an MCAP Schema record holds."""
    return json.dumps(schema, separators=(",", ":")).encode()


def _wide(nav: pl.DataFrame, needed: tuple[str, ...], optional: tuple[str, ...]) -> pl.DataFrame:
    """One row per time any of the variables was posted, with the latest of each."""
    import polars as pl

    wanted = [*needed, *optional]
    rows = nav.filter(pl.col("variable").is_in(wanted))
    if not set(needed) <= set(rows["variable"].unique().to_list()):
        return pl.DataFrame()
    wide = (
        rows.pivot(on="variable", index="log_time", values="double", aggregate_function="last")
        .sort("log_time")
        .with_columns(pl.exclude("log_time").forward_fill())
    )
    for name in optional:
        if name not in wide.columns:
            wide = wide.with_columns(pl.lit(0.0).alias(name))
    wide = wide.drop_nulls(list(needed))
    if optional:
        wide = wide.with_columns(pl.col(list(optional)).fill_null(0.0))
    return wide


def _stamp() -> pl.Expr:
    import polars as pl

    return pl.struct(
        sec=(pl.col("log_time") // 1_000_000_000).cast(pl.Int64),
        nsec=(pl.col("log_time") % 1_000_000_000).cast(pl.Int64),
    )


def locations(nav: pl.DataFrame, vehicle: str) -> pl.DataFrame:
    """``foxglove.LocationFix`` messages (``log_time``, ``data``) from NAV_LAT/NAV_LONG."""
    import polars as pl

    wide = _wide(nav, LOCATION_VARS, ())
    if not wide.height:
        return pl.DataFrame(schema={"log_time": pl.UInt64, "data": pl.String})
    return wide.select(
        "log_time",
        data=pl.struct(
            timestamp=_stamp(),
            frame_id=pl.lit(vehicle),
            latitude=pl.col("NAV_LAT"),
            longitude=pl.col("NAV_LONG"),
            altitude=pl.lit(0.0),
            position_covariance=pl.lit(pl.Series([[0.0] * 9])),
            position_covariance_type=pl.lit(0),
        ).struct.json_encode(),
    )


def poses(nav: pl.DataFrame) -> pl.DataFrame:
    """``foxglove.PoseInFrame`` messages (``log_time``, ``data``) from NAV_X/Y/HEADING."""
    import polars as pl

    wide = _wide(nav, POSE_VARS, ("NAV_Z",))
    if not wide.height:
        return pl.DataFrame(schema={"log_time": pl.UInt64, "data": pl.String})
    half_yaw = (90.0 - pl.col("NAV_HEADING")) * (math.pi / 360.0)
    return wide.select(
        "log_time",
        data=pl.struct(
            timestamp=_stamp(),
            frame_id=pl.lit(POSE_FRAME),
            pose=pl.struct(
                position=pl.struct(x=pl.col("NAV_X"), y=pl.col("NAV_Y"), z=pl.col("NAV_Z")),
                orientation=pl.struct(
                    x=pl.lit(0.0), y=pl.lit(0.0), z=half_yaw.sin(), w=half_yaw.cos()
                ),
            ),
        ).struct.json_encode(),
    )
