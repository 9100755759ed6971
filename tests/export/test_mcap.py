"""MCAP exports re-read by the ``mcap`` package's reader: Foxglove's view of the alog."""

from __future__ import annotations

import base64
import io
import json
import math
import random
from pathlib import Path

import polars as pl
import pytest
from export.support import IVP, REFERENCE_ALOGS, THEMOOS, expected, same_double
from mcap.reader import make_reader

from fleetlog.export import Tally, export_mcap, resolve
from fleetlog.export.mcapfile import McapWriter
from fleetlog.storage.outputs import atomic_output


def export(sources: list[Path], out: Path, **options: object) -> tuple[Tally, object]:
    tally = Tally()
    with atomic_output(out) as f:
        result = export_mcap(resolve(sources).sources, f, tally, **options)  # type: ignore[arg-type]
    return tally, result


def messages(path: Path) -> list[tuple[str, str, str, int, int, dict[str, object]]]:
    out = []
    with path.open("rb") as f:
        reader = make_reader(f, validate_crcs=True)
        for schema, channel, message in reader.iter_messages(log_time_order=True):
            assert schema is not None
            out.append(
                (
                    channel.topic,
                    schema.name,
                    channel.message_encoding,
                    message.log_time,
                    message.publish_time,
                    json.loads(message.data),
                )
            )
    return out


@pytest.mark.parametrize("alog", REFERENCE_ALOGS, ids=lambda p: p.parent.name)
def test_mcap_round_trip_through_the_mcap_reader(alog: Path, tmp_path: Path) -> None:
    out = tmp_path / "x.mcap"
    tally, _ = export([alog], out, positions=False)
    want = expected(alog)
    vehicle = resolve([alog]).sources[0].vehicle
    got = messages(out)
    assert tally.entries == len(want) == len(got)
    ref = sorted(want, key=lambda w: (w.time_ns, w.variable, str(w.double), str(w.string)))
    mine = sorted(
        got, key=lambda m: (m[3], m[0].rsplit("/", 1)[1], str(m[5]["value"]), str(m[5]["value"]))
    )
    # same multiset of (time, variable): compare per time and variable in a stable way
    assert [(m[3], m[0]) for m in sorted(got, key=lambda m: (m[3], m[0]))] == sorted(
        (w.time_ns, f"/{vehicle}/{w.variable}") for w in want
    )
    by_key: dict[tuple[int, str], list[dict[str, object]]] = {}
    for topic, schema, encoding, log_time, publish_time, data in mine:
        assert schema == "fleetlog.MoosValue"
        assert encoding == "json"
        assert publish_time == log_time
        by_key.setdefault((log_time, topic), []).append(data)
    for w in ref:
        assert w.time_ns is not None
        candidates = by_key[(w.time_ns, f"/{vehicle}/{w.variable}")]
        match = None
        for data in candidates:
            value = data["value"]
            if w.type == "double":
                ok = (
                    value is None and not math.isfinite(w.double)  # type: ignore[arg-type]
                ) or (isinstance(value, float | int) and same_double(float(value), w.double))
            elif w.type == "binary":
                ok = value == (None if w.binary is None else base64.b64encode(w.binary).decode())
            else:
                ok = value == w.string
            if ok and (data["source"], data["aux"], data["community"]) == (
                w.source,
                w.aux,
                w.community,
            ):
                match = data
                break
        assert match is not None, (w, candidates)
        candidates.remove(match)


def test_the_file_is_indexed_and_chunked_with_zstd(tmp_path: Path) -> None:
    out = tmp_path / "x.mcap"
    export([IVP], out)
    with out.open("rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None
    assert summary.statistics is not None
    assert summary.chunk_indexes
    assert all(c.compression == "zstd" for c in summary.chunk_indexes)
    assert all(c.message_index_offsets for c in summary.chunk_indexes)
    assert summary.statistics.message_count == sum(
        summary.statistics.channel_message_counts.values()
    )
    topics = {c.topic for c in summary.channels.values()}
    assert "/alpha/NAV_X" in topics
    assert "/alpha/pose" in topics
    assert "/alpha/location" in topics
    value = next(s for s in summary.schemas.values() if s.name == "fleetlog.MoosValue")
    assert value.encoding == "jsonschema"
    assert set(json.loads(value.data)["properties"]) == {"value", "source", "aux", "community"}


def test_positions_for_foxglove_map_and_3d_panels(tmp_path: Path) -> None:
    out = tmp_path / "x.mcap"
    _, _result = export([IVP], out)
    got = messages(out)
    poses = [m for m in got if m[0] == "/alpha/pose"]
    fixes = [m for m in got if m[0] == "/alpha/location"]
    assert {m[1] for m in poses} == {"foxglove.PoseInFrame"}
    assert {m[1] for m in fixes} == {"foxglove.LocationFix"}
    # NAV_X, NAV_Y, NAV_HEADING first together at 1.35116; then NAV_Z, then NAV_X again
    assert len(poses) == 3
    first = poses[0][5]
    assert first["frame_id"] == "map"
    assert first["pose"]["position"] == {"x": 0.0, "y": -20.0, "z": 0.0}  # type: ignore[index]
    q = first["pose"]["orientation"]  # type: ignore[index]
    # heading 180 (south, compass) is yaw -90 degrees about +z from east
    assert math.isclose(q["z"], -math.sqrt(0.5))
    assert math.isclose(q["w"], math.sqrt(0.5))
    stamp = first["timestamp"]
    assert stamp["sec"] * 10**9 + stamp["nsec"] == poses[0][3]  # type: ignore[index]
    assert poses[2][5]["pose"]["position"]["x"] == 0.52211  # type: ignore[index]
    assert len(fixes) == 1
    fix = fixes[0][5]
    assert (fix["latitude"], fix["longitude"]) == (43.82512, -70.3304)
    assert fix["frame_id"] == "alpha"


def test_several_vehicles_one_channel_each_per_variable(tmp_path: Path) -> None:
    out = tmp_path / "x.mcap"
    export([IVP, THEMOOS], out)
    with out.open("rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None
    topics = [c.topic for c in summary.channels.values()]
    assert len(topics) == len(set(topics))
    assert "/alpha/NAV_X" in topics
    assert f"/{THEMOOS.name}/NAV_X" in topics


def test_writer_orders_by_time_within_a_batch_and_cuts_chunks(tmp_path: Path) -> None:
    buf = io.BytesIO()
    writer = McapWriter(buf, chunk_size=1024)
    sid = writer.add_schema("s", "jsonschema", b"{}")
    a = writer.add_channel("/a", "json", sid)
    b = writer.add_channel("/b", "json", sid)
    n = 500
    times = [(n - i) * 1000 for i in range(n)]  # reversed
    writer.write_batch(
        pl.DataFrame(
            {
                "channel": [a if i % 3 else b for i in range(n)],
                "log_time": times,
                "data": [f'{{"i":{i}}}'.encode() for i in range(n)],
            }
        )
    )
    writer.finish()
    buf.seek(0)
    reader = make_reader(buf, validate_crcs=True)
    summary = reader.get_summary()
    assert summary is not None
    assert len(summary.chunk_indexes) > 5
    got = [(m.log_time, c.topic) for _, c, m in reader.iter_messages()]
    assert [t for t, _ in got] == sorted(times)
    assert summary.statistics is not None
    assert summary.statistics.channel_message_counts == {a: n - (n + 2) // 3, b: (n + 2) // 3}


def test_a_log_without_logstart_is_counted_not_written(tmp_path: Path) -> None:
    alog = tmp_path / "x.alog"
    alog.write_bytes(b"0.5             NAV_X                pNav            1.0 \n")
    out = tmp_path / "x.mcap"
    tally, result = export([alog], out)
    assert result.untimed == 1  # type: ignore[attr-defined]
    assert tally.no_logstart == [str(alog)]
    assert messages(out) == []


def test_numpy_and_pure_python_assembly_write_the_same_bytes() -> None:
    # numpy is an optional accelerator: without it, the pure-Python path must give the same file
    rng = random.Random(3)
    n = 5000
    frame = pl.DataFrame(
        {
            "channel": [rng.randint(0, 5) for _ in range(n)],
            "log_time": [rng.randint(0, 10**12) for _ in range(n)],
            "data": [f'{{"v":{rng.random()!r},"s":"é\\n"}}' for _ in range(n)],
        }
    )
    files = []
    for accelerate in (False, True):
        buf = io.BytesIO()
        writer = McapWriter(buf, chunk_size=4096, accelerate=accelerate)
        sid = writer.add_schema("s", "jsonschema", b"{}")
        for i in range(6):
            writer.add_channel(f"/c{i}", "json", sid)
        writer.write_batch(frame)
        writer.write_batch(frame.head(7))
        # bytes that are not UTF-8 text, and a message without data
        writer.write_batch(
            pl.DataFrame(
                {"channel": [1, 2], "log_time": [5, 6], "data": [b"\xff\xfe", None]},
                schema={"channel": pl.UInt16, "log_time": pl.UInt64, "data": pl.Binary},
            )
        )
        writer.finish()
        files.append(buf.getvalue())
    assert files[0] == files[1]
    reader = make_reader(io.BytesIO(files[1]), validate_crcs=True)
    assert sum(1 for _ in reader.iter_messages()) == n + 7 + 2


def test_message_text_splits_each_source_and_escapes_every_string() -> None:
    # Each distinct source column is split and written once, then looked up by row: every
    # message must still carry its own row's source, aux, community and value, whatever
    # characters they hold.
    from fleetlog.export.tomcap import _messages
    from fleetlog.moos.alog import split_source

    rng = random.Random(7)
    texts = ["", "pNav", "é ü 😀", "a/b", "\x7f", "\u2028", 'say "hi"', "back\\slash", "tab\t"]
    texts += ["nl\n", "\x00", "\x1f"]
    sources = ["pNav", "pHelm:HELM_INIT", "pMV@shoreside", "a:b:c@d@e", ":@", *texts]
    sources += [f"{a}:{b}@{c}" for a, b, c in zip(texts, reversed(texts), texts[3:], strict=False)]
    specials = [float("nan"), float("inf"), -float("inf"), -0.0, 1e-7, 1e300, 3.0]
    rows = []
    for _ in range(2000):
        kind = rng.choice(["double", "string", "binary"])
        text = rng.choice(texts)
        rows.append(
            {
                "log_time": rng.randint(0, 10**12),
                "source": rng.choice(sources),
                "type": kind,
                "double": rng.choice(specials) if kind == "double" else None,
                "string": None if kind == "double" else text,
                "binary": rng.choice([text.encode(), None]) if kind == "binary" else None,
            }
        )
    schema = {
        "log_time": pl.UInt64,
        "source": pl.String,
        "type": pl.String,
        "double": pl.Float64,
        "string": pl.String,
        "binary": pl.Binary,
    }
    whole = pl.DataFrame(rows, schema=schema)
    finite = whole.filter(pl.col("double").is_finite() | pl.col("double").is_null())
    for frame in (whole, whole.filter(pl.col("type") != "binary"), whole.head(1), finite):
        frame = frame.with_columns(channel=pl.lit(0, pl.UInt16))
        got = _messages(frame)["data"].to_list()
        assert len(got) == frame.height
        for text, row in zip(got, frame.iter_rows(named=True), strict=True):
            message = json.loads(text)
            src, aux, community = split_source(row["source"])
            assert (message["source"], message["aux"], message["community"]) == (
                src,
                aux,
                community,
            )
            if row["type"] == "string":
                assert message["value"] == row["string"]
            elif row["type"] == "double":
                finite = math.isfinite(row["double"])
                assert message["value"] == (row["double"] if finite else None)
            else:
                binary = row["binary"]
                want = None if binary is None else base64.b64encode(binary).decode()
                assert message["value"] == want


def test_derived_json_text_is_what_json_encode_writes() -> None:
    # foxglove.py writes the position messages as text (faster); json_encode is the oracle
    from fleetlog.export.foxglove import locations, poses

    rng = random.Random(5)
    specials = [float("nan"), float("inf"), -float("inf"), 0.0, -0.0, 1e16, 1e-7, 5e-324, 1e308]
    rows = []
    for i in range(400):
        for var in ("NAV_X", "NAV_Y", "NAV_HEADING", "NAV_Z", "NAV_LAT", "NAV_LONG"):
            value = rng.choice(specials) if rng.random() < 0.2 else rng.uniform(-1e6, 1e6)
            rows.append((1_750_000_000_000_000_000 + i * 123_456_789, var, value))
    nav = pl.DataFrame(
        rows,
        schema={"log_time": pl.UInt64, "variable": pl.String, "double": pl.Float64},
        orient="row",
    )
    vehicle = 'v"é\\1'
    half_yaw = (90.0 - pl.col("NAV_HEADING")) * (math.pi / 360.0)
    stamp = pl.struct(
        sec=(pl.col("log_time") // 1_000_000_000).cast(pl.Int64),
        nsec=(pl.col("log_time") % 1_000_000_000).cast(pl.Int64),
    )
    oracle_pose = pl.struct(
        timestamp=stamp,
        frame_id=pl.lit("map"),
        pose=pl.struct(
            position=pl.struct(x=pl.col("NAV_X"), y=pl.col("NAV_Y"), z=pl.col("NAV_Z")),
            orientation=pl.struct(x=pl.lit(0.0), y=pl.lit(0.0), z=half_yaw.sin(), w=half_yaw.cos()),
        ),
    ).struct.json_encode()
    oracle_fix = pl.struct(
        timestamp=stamp,
        frame_id=pl.lit(vehicle),
        latitude=pl.col("NAV_LAT"),
        longitude=pl.col("NAV_LONG"),
        altitude=pl.lit(0.0),
        position_covariance=pl.lit(pl.Series([[0.0] * 9])),
        position_covariance_type=pl.lit(0),
    ).struct.json_encode()
    # also: no NAV_Z (z is 0.0 throughout), and only finite values (no null test)
    no_z = nav.filter(pl.col("variable") != "NAV_Z")
    for rows in (nav, no_z, nav.filter(pl.col("double").is_finite())):
        for derived, oracle in (
            (poses(rows), oracle_pose),
            (locations(rows, vehicle), oracle_fix),
        ):
            assert derived.rows.height > 200
            got = derived.frame()["data"].to_list()
            assert got == derived.rows.select(oracle).to_series().to_list()
            assert all(isinstance(json.loads(text), dict) for text in got)


def test_derived_rows_are_the_latest_values_at_each_time() -> None:
    # The oracle is a pivot (the last value posted at each time, forward-filled): times
    # repeated and out of file order, NaN values, variables missing at first.
    from fleetlog.export.foxglove import _wide

    rng = random.Random(11)
    for _ in range(150):
        names = rng.sample(["NAV_X", "NAV_Y", "NAV_HEADING", "NAV_Z", "OTHER"], rng.randint(1, 5))
        t, rows = 0, []
        for i in range(rng.randint(0, 60)):
            t = max(0, t + (rng.choice([0, 0, 1, 2]) if rng.random() < 0.9 else -rng.randint(0, 3)))
            rows.append((t, rng.choice(names), rng.choice([float(i), float("nan"), -float(i)])))
        nav = pl.DataFrame(
            rows,
            schema={"log_time": pl.UInt64, "variable": pl.String, "double": pl.Float64},
            orient="row",
        )
        for needed, optional in ((("NAV_X", "NAV_Y", "NAV_HEADING"), ("NAV_Z",)), (("NAV_X",), ())):
            got, _ = _wide(nav, needed, optional)
            present = set(nav["variable"].to_list())
            if not set(needed) <= present:
                assert got.height == 0
                continue
            want = (
                nav.filter(pl.col("variable").is_in([*needed, *optional]))
                .pivot(on="variable", index="log_time", values="double", aggregate_function="last")
                .sort("log_time")
                .with_columns(pl.exclude("log_time").forward_fill())
            )
            for name in optional:
                if name not in want.columns:
                    want = want.with_columns(pl.lit(0.0).alias(name))
            want = want.drop_nulls(list(needed)).with_columns(pl.col(list(optional)).fill_null(0.0))
            columns = ["log_time", *needed, *optional]
            assert got.select(columns).equals(want.select(columns)), nav


def test_derived_channels_in_slices_and_the_same_file_every_time(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    # A long derived channel is written in slices by the workers; the file never depends on
    # the threads' timing, and slicing changes only where chunks end.
    import fleetlog.export.tomcap as tomcap

    whole, again, sliced = tmp_path / "a.mcap", tmp_path / "b.mcap", tmp_path / "c.mcap"
    export([IVP, THEMOOS], whole)
    export([IVP, THEMOOS], again)
    assert whole.read_bytes() == again.read_bytes()
    monkeypatch.setattr(tomcap, "_SLICE", 1)
    export([IVP, THEMOOS], sliced)
    assert messages(sliced) == messages(whole)
