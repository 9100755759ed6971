"""Generated alogs for the reader's property tests: every shape MOOS_FORMAT.md §12 names.

Fields wider than their columns, empty sources and values, multi-line values, MarkDataType
switched on mid-file, binary references and strings that look like them, doubles padded and
not, stray lines, comments, bytes that are not UTF-8, and cut tails (:func:`alog_bytes`).
With ``plain``, most files have no continuation or stray line at all (the blocks a selective
read cuts only in part), and some have one, somewhere.
"""

from __future__ import annotations

from hypothesis import strategies as st

from fleetlog.moos.alog import format_banner

BANNER = format_banner("./g/g.alog", 1750334690.048564, "Thu Jan  1 00:00:00 1970")

NAMES = "ABXYZ_09é"
SOURCES = "pHelm:IvP@ab_9"
_name = st.text(st.sampled_from(NAMES), min_size=1, max_size=24)
_source = st.text(st.sampled_from(SOURCES), min_size=0, max_size=20)
_time = st.sampled_from(["0.5", "12.25000", "-3.5", "1e3", "100000000000000.1", "7", "1."])
_value = st.one_of(
    st.sampled_from(
        [
            "1.50000     ",
            "-0.00000    ",
            "123456789.12346",
            "0.5",
            "nan         ",
            "D:2.00000      ",
            "S:true",
            "S:",
            "D:x",
            "<MOOS_BINARY>File=g.blog,Offset=53,Bytes=16</MOOS_BINARY>",
            "",
            "  lead",
            "a\r",
        ]
    ),
    st.text(st.sampled_from("ab =,\n%1 -\x00\u00e9"), max_size=30),
)


@st.composite
def alog_line(draw: st.DrawFn, plain: bool = False) -> str:
    """One line of a log: an entry (maybe of several lines), a comment or a stray line."""
    kind = draw(st.integers(0, 9))
    if kind == 0:
        others = ["% a comment", "%% DATATYPE MARKING ON"]
        return draw(st.sampled_from(others if plain else [*others, "stray", ""]))
    time_text, key, source = draw(_time), draw(_name), draw(_source)
    value = draw(_value)
    if plain:
        value = value.replace("\n", "")
    end = "" if value.startswith("<MOOS") and draw(st.booleans()) else " "
    return f"{time_text.ljust(15)} {key.ljust(20)} {source.ljust(15)} {value}{end}"


@st.composite
def alog_bytes(draw: st.DrawFn, plain: bool = False) -> bytes:
    """A whole log, banner or not, maybe with bytes that are not UTF-8 and a cut tail."""
    lines = draw(st.lists(alog_line(plain), max_size=40))
    if plain and lines and draw(st.booleans()):
        # one continuation, stray or malformed entry line, somewhere
        odd = draw(st.sampled_from(["stray", "", "12 starts like an entry", "-1.5 x", "7"]))
        lines.insert(draw(st.integers(0, len(lines))), odd)
    body = "\n".join(lines)
    head = BANNER if draw(st.booleans()) else ""
    data = (head + body + "\n").encode()
    if draw(st.booleans()):
        data = data.replace(b"a", b"\xff", draw(st.integers(0, 3)))
    cut = draw(st.integers(0, 6))
    return data[: len(data) - cut] if cut else data
