"""LineFormatter's one-operation double line is format_entry's line, byte for byte."""

from __future__ import annotations

import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from fleetlog.moos.alog import LineFormatter, Variant, format_double, format_entry

offsets = st.floats(min_value=-1e3, max_value=1e7, allow_nan=False)
doubles = st.floats()  # NaN (both signs), infinities, subnormals, huge values included
keys = st.text(alphabet="ABCXYZ_0123456789", min_size=1, max_size=30)


@given(offsets, keys, doubles, st.integers(0, 15), st.booleans(), st.sampled_from(Variant))
def test_double_line_is_format_entry(
    offset: float, key: str, value: float, precision: int, mark: bool, variant: Variant
) -> None:
    fmt = LineFormatter(variant, precision, mark_data_type=mark)
    text = ("D:" if mark else "") + format_double(value, precision)
    expected = format_entry(offset, key, "iGPS", text, variant=variant)
    assert fmt.double(offset, key, "iGPS", value) == expected


@pytest.mark.parametrize("value", [math.nan, -math.nan, math.inf, -math.inf, -0.0, 3])
def test_double_special_values(value: float) -> None:
    fmt = LineFormatter()
    expected = format_entry(1.0, "X", "src", format_double(value))
    assert fmt.double(1.0, "X", "src", value) == expected


def test_settings_changed_after_construction_apply() -> None:
    fmt = LineFormatter()
    fmt.double_precision = 2
    fmt.mark_data_type = True
    assert (fmt.double_precision, fmt.mark_data_type) == (2, True)
    assert fmt.double(1.0, "X", "src", 1.234) == format_entry(1.0, "X", "src", "D:1.23        ")
    assert fmt.string(1.0, "X", "src", "v") == format_entry(1.0, "X", "src", "S:v")
