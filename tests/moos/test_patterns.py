"""Tests for fleetlog.moos.patterns: name escaping, MOOS globs, key chunks, the §6.4 table."""

from __future__ import annotations

import itertools
import string
import subprocess
import sys

import pytest
import zenoh
from hypothesis import assume, example, given, settings
from hypothesis import strategies as st

from fleetlog.errors import FormatError
from fleetlog.moos.patterns import (
    ALWAYS_LOGGED,
    EMPTY_NAME_CHUNK,
    MoosGlob,
    Verdict,
    WildcardClassifier,
    chunk_includes,
    chunk_to_name,
    glob_match,
    glob_to_chunk,
    globs_to_key_suffixes,
    name_to_chunk,
    reduce_chunks,
)

PREFIX = "fleet/v/var/"
ALPHABET = "AB_*?/$#@%." + string.digits
LITERALS = "AB_/$#@%." + string.digits  # what a wildcard may stand for, plus '*' and '?'

names = st.text(alphabet=ALPHABET, max_size=8)
globs = st.text(alphabet=ALPHABET, max_size=8)
any_text = st.text(max_size=12)
byte_names = st.binary(max_size=12).map(lambda b: b.decode("utf-8", "surrogateescape"))


def key(chunk: str) -> zenoh.KeyExpr:
    return zenoh.KeyExpr(PREFIX + chunk)


def moos_wild_cmp(pattern: str, text: str) -> bool:
    """A line-by-line port of MOOSWildCmp (Jack Handy's wildcmp), the reference matcher."""
    w = s = 0
    cp = mp = -1
    while s < len(text) and (w >= len(pattern) or pattern[w] != "*"):
        if w >= len(pattern) or (pattern[w] != text[s] and pattern[w] != "?"):
            return False
        w += 1
        s += 1
    while s < len(text):
        if w < len(pattern) and pattern[w] == "*":
            w += 1
            if w >= len(pattern):
                return True
            mp = w
            cp = s + 1
        elif w < len(pattern) and (pattern[w] == text[s] or pattern[w] == "?"):
            w += 1
            s += 1
        else:
            w = mp
            s = cp
            cp += 1
    while w < len(pattern) and pattern[w] == "*":
        w += 1
    return w >= len(pattern)


@st.composite
def glob_and_matching_name(draw: st.DrawFn) -> tuple[str, str]:
    """A glob and a name built from it by substituting its wildcards, so it matches."""
    pattern = draw(globs)
    parts = []
    for char in pattern:
        if char == "*":
            parts.append(draw(st.text(alphabet=ALPHABET, max_size=3)))
        elif char == "?":
            parts.append(draw(st.sampled_from(ALPHABET)))
        else:
            parts.append(char)
    return pattern, "".join(parts)


# --------------------------------------------------------------------------------------------
# Names <-> chunks


@pytest.mark.parametrize(
    ("name", "chunk"),
    [
        ("NAV_X", "NAV_X"),
        ("#1", "%231"),
        ("", EMPTY_NAME_CHUNK),
        ("%", "%25"),
        ("a/b", "a%2Fb"),
        ("*", "%2A"),
        ("**", "%2A%2A"),
        ("$x", "%24x"),
        ("why?", "why%3F"),
        ("@shore", "%40shore"),
        ("a@b", "a@b"),
        ("@@", "%40@"),
        ("a b", "a b"),
        ("%00", "%2500"),
        ("\x00", "\x00"),
        ("é", "é"),
        ("x\udcff", "x%FF"),
    ],
)
def test_name_to_chunk_examples(name: str, chunk: str) -> None:
    assert name_to_chunk(name) == chunk
    assert chunk_to_name(chunk) == name
    zenoh.KeyExpr(PREFIX + chunk)


@settings(max_examples=500)
@given(st.one_of(names, any_text, byte_names))
@example("")
@example("@")
@example("$*")
def test_name_chunk_is_valid_and_reversible(name: str) -> None:
    chunk = name_to_chunk(name)
    assert chunk
    assert "/" not in chunk
    assert str(key(chunk)) == PREFIX + chunk  # accepted as is: valid and canonical
    assert key(chunk).includes(key(chunk))
    assert chunk_to_name(chunk) == name


@settings(max_examples=300)
@given(names, names)
def test_distinct_names_never_share_a_key(a: str, b: str) -> None:
    assume(a != b)
    assert not key(name_to_chunk(a)).intersects(key(name_to_chunk(b)))


@settings(max_examples=500)
@given(st.text(alphabet="%@AB*$/#?0123456789DEFCcf\x00", max_size=8))
def test_chunk_to_name_accepts_only_canonical_chunks(chunk: str) -> None:
    try:
        name = chunk_to_name(chunk)
    except FormatError:
        return
    assert name_to_chunk(name) == chunk


@pytest.mark.parametrize(
    "chunk",
    ["", "%", "%2", "%2f", "%ZZ", "a%40", "@x", "a*", "$*", "a/b", "x?", "#1", "%0", "a%00"],
)
def test_chunk_to_name_rejects_malformed(chunk: str) -> None:
    with pytest.raises(FormatError):
        chunk_to_name(chunk)


def test_name_with_unencodable_surrogate() -> None:
    with pytest.raises(FormatError, match="surrogate"):
        name_to_chunk("a\ud800")
    with pytest.raises(FormatError, match="surrogate"):
        glob_to_chunk("*\ud800")


# --------------------------------------------------------------------------------------------
# MoosGlob


@pytest.mark.parametrize(
    ("pattern", "name", "expected"),
    [
        ("*", "", True),
        ("*", "ANY", True),
        ("", "", True),
        ("", "A", False),
        ("NAV_*", "NAV_X", True),
        ("NAV_*", "NAV_", True),
        ("NAV_*", "nav_x", False),  # case-sensitive
        ("nav_*", "NAV_X", False),
        ("*_STATUS", "HELM_STATUS", True),
        ("*_STATUS", "HELM_STATUSX", False),
        ("NAV_?", "NAV_X", True),
        ("NAV_?", "NAV_", False),
        ("NAV_?", "NAV_XY", False),
        ("?", "", False),
        ("A*B*C", "AxxBxxC", True),
        ("A*B*C", "AxxBxx", False),
        ("a.b", "aXb", False),  # '.' is literal
        ("[A]", "[A]", True),  # no character classes
        ("[A]", "A", False),
        ("a\nb*", "a\nbc", True),
    ],
)
def test_moos_glob_examples(pattern: str, name: str, expected: bool) -> None:
    assert MoosGlob(pattern).matches(name) is expected
    assert moos_wild_cmp(pattern, name) is expected


@settings(max_examples=500)
@given(globs, names)
def test_moos_glob_agrees_with_moos_wild_cmp(pattern: str, name: str) -> None:
    assert MoosGlob(pattern).matches(name) is moos_wild_cmp(pattern, name)


@settings(max_examples=300)
@given(glob_and_matching_name())
def test_moos_glob_matches_names_built_from_it(pair: tuple[str, str]) -> None:
    pattern, name = pair
    assert MoosGlob(pattern).matches(name)
    assert moos_wild_cmp(pattern, name)


# A wider alphabet and longer strings than `globs`/`names`: repeated letters make many
# partial matches, the hardest case for a matcher that places segments greedily.
dense_globs = st.text(alphabet="ab?*", max_size=14)
dense_names = st.text(alphabet="ab?*", max_size=24)


@settings(max_examples=2000)
@given(dense_globs, dense_names)
def test_moos_glob_agrees_with_moos_wild_cmp_on_dense_text(pattern: str, name: str) -> None:
    assert MoosGlob(pattern).matches(name) is moos_wild_cmp(pattern, name)
    assert glob_match(pattern, name) is moos_wild_cmp(pattern, name)


@settings(max_examples=300)
@given(st.text(max_size=10), st.text(max_size=30))
def test_moos_glob_agrees_with_moos_wild_cmp_on_any_text(pattern: str, name: str) -> None:
    assert MoosGlob(pattern).matches(name) is moos_wild_cmp(pattern, name)


# Each of these took a backtracking matcher (a regular expression `.*a.*a...`) minutes to
# centuries on the name below (issue 10, item 2); a matcher that never backtracks answers in
# milliseconds. They run in a child process because a regular expression stuck in C can be
# stopped no other way; the 60 s limit only tells a hang from an answer.
HOSTILE_GLOBS = [
    "*a*a*a*a*a*a*a*b",
    "*a*a*a*a*a*a*a*a*a*a*a*a*a*a*a*a*b*",
    "*a?a*a?a*a?a*a?a*a?a*b",
    "*?*?*?*?*?*?*?*?*?*?*?*?*b",
    "a*a*a*a*a*a*a*a*a*a*a*a*a*a*a*a*a*a*a*a*a*a*a*a*a*a*a*a*a*a*a*b",
]


def test_moos_glob_never_backtracks_on_hostile_patterns() -> None:
    script = (
        "from fleetlog.moos.patterns import MoosGlob\n"
        f"globs = {HOSTILE_GLOBS!r}\n"
        "for name in ('a' * 200_000, 'ab' * 100_000, 'a' * 199_999 + 'b'):\n"
        "    for g in globs:\n"
        "        print(int(MoosGlob(g).matches(name)), end='')\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, timeout=60, check=True
    )
    expected = "".join(
        str(int(moos_wild_cmp(g, n)))
        for n in ("a" * 2_000, "ab" * 1_000, "a" * 1_999 + "b")
        for g in HOSTILE_GLOBS
    )
    assert done.stdout == expected


def test_moos_glob_value_semantics() -> None:
    assert MoosGlob("A*") == MoosGlob("A*")
    assert hash(MoosGlob("A*")) == hash(MoosGlob("A*"))
    assert MoosGlob("A*") != MoosGlob("A?")
    assert repr(MoosGlob("A*")) == "MoosGlob('A*')"
    assert MoosGlob("A?").has_wildcards
    assert not MoosGlob("AB").has_wildcards
    assert MoosGlob("NAV_*").chunk == "NAV_$*"


# --------------------------------------------------------------------------------------------
# Globs -> key chunks


@pytest.mark.parametrize(
    ("pattern", "chunk"),
    [
        ("*", "*"),
        ("**", "*"),
        ("?", "*"),
        ("*?*", "*"),
        ("NAV_X", "NAV_X"),
        ("NAV_*", "NAV_$*"),
        ("*_STATUS", "$*_STATUS"),
        ("NAV_?", "NAV_$*"),
        ("A*?B", "A$*B"),
        ("A**B", "A$*B"),
        ("*A*", "$*A$*"),
        ("", EMPTY_NAME_CHUNK),
        ("#1", "%231"),
        ("#*", "%23$*"),
        ("a/*", "a%2F$*"),
        ("%*$", "%25$*%24"),
        ("@x", "%40x"),
        ("@x*", "%40x$*"),
        ("a@b*", "a@b$*"),
        ("?@x", "$*@x"),  # '@' at position >= 1
        ("*@x", "$*x"),  # '@' may be at position 0 (then %40) or later (then @)
        ("**@x*", "$*x$*"),
        ("*@", "*"),
        ("*a@", "$*a@"),
    ],
)
def test_glob_to_chunk_examples(pattern: str, chunk: str) -> None:
    assert glob_to_chunk(pattern) == chunk
    zenoh.KeyExpr(PREFIX + chunk)


@settings(max_examples=500)
@given(globs)
def test_glob_chunk_is_a_valid_single_chunk(pattern: str) -> None:
    chunk = glob_to_chunk(pattern)
    assert chunk
    assert "/" not in chunk
    assert str(key(chunk)) == PREFIX + chunk  # valid and already canonical
    if not MoosGlob(pattern).has_wildcards:
        assert chunk == name_to_chunk(pattern)


@settings(max_examples=500)
@given(glob_and_matching_name())
@example(("*@x", "@x"))
@example(("**@*", "@"))
@example(("*", ""))
@example(("@*", "@"))
@example(("*%*", "%"))
def test_glob_key_includes_every_matching_name(pair: tuple[str, str]) -> None:
    """The property that matters: a key expression never admits too little."""
    pattern, name = pair
    assert MoosGlob(pattern).matches(name)
    glob_key = key(glob_to_chunk(pattern))
    name_key = key(name_to_chunk(name))
    assert glob_key.includes(name_key)
    assert glob_key.intersects(name_key)


@settings(max_examples=500)
@given(globs, names)
def test_glob_key_includes_every_matching_random_name(pattern: str, name: str) -> None:
    if MoosGlob(pattern).matches(name):
        assert key(glob_to_chunk(pattern)).includes(key(name_to_chunk(name)))


@settings(max_examples=300)
@given(st.one_of(names, any_text, byte_names))
def test_literal_glob_key_is_exactly_the_name(name: str) -> None:
    assume("*" not in name and "?" not in name)
    assert glob_to_chunk(name) == name_to_chunk(name)


@pytest.mark.parametrize(
    ("pattern", "other"),
    [("NAV_*", "NAV"), ("NAV_*", "XNAV_Y"), ("*_STATUS", "STATUS"), ("A*B", "AC"), ("@x", "x")],
)
def test_glob_key_is_narrow(pattern: str, other: str) -> None:
    assert not key(glob_to_chunk(pattern)).intersects(key(name_to_chunk(other)))


# --------------------------------------------------------------------------------------------
# Chunk inclusion and reduction


@pytest.mark.parametrize(
    ("outer", "inner", "expected"),
    [
        ("*", "A$*", True),
        ("*", "*", True),
        ("A$*", "*", False),
        ("A$*", "AB$*", True),
        ("A$*", "A", True),
        ("AB$*", "A$*", False),
        ("$*B", "A$*B", True),
        ("$*B", "A$*", False),
        ("A$*B$*C", "AxB$*yC", True),
        ("A$*B", "A$*B", True),
        ("NAV_X", "NAV_X", True),
        ("NAV_X", "NAV_Y", False),
    ],
)
def test_chunk_includes_examples(outer: str, inner: str, expected: bool) -> None:
    assert chunk_includes(outer, inner) is expected
    if expected:
        assert key(outer).includes(key(inner))


@settings(max_examples=500)
@given(globs, globs)
def test_chunk_includes_is_sound(a: str, b: str) -> None:
    outer, inner = glob_to_chunk(a), glob_to_chunk(b)
    if chunk_includes(outer, inner):
        assert key(outer).includes(key(inner))


@settings(max_examples=300)
@given(st.lists(globs, max_size=6))
def test_globs_to_key_suffixes_covers_every_glob_without_redundancy(patterns: list[str]) -> None:
    reduced = globs_to_key_suffixes(patterns)
    for pattern in patterns:
        assert any(key(c).includes(key(glob_to_chunk(pattern))) for c in reduced)
    assert len(set(reduced)) == len(reduced)
    for a, b in itertools.permutations(reduced, 2):
        assert not chunk_includes(a, b)
    assert set(reduced) <= {glob_to_chunk(p) for p in patterns}


def test_globs_to_key_suffixes_examples() -> None:
    assert globs_to_key_suffixes([]) == []
    assert globs_to_key_suffixes(["NAV_*", "*", "X"]) == ["*"]
    assert globs_to_key_suffixes(["NAV_*", "NAV_X", "NAV_?", "*_X", "N*"]) == ["$*_X", "N$*"]
    assert globs_to_key_suffixes(["NAV_*", "NAV_?", "A"]) == ["NAV_$*", "A"]
    assert reduce_chunks(["A", "A", "B"]) == ["A", "B"]


# --------------------------------------------------------------------------------------------
# The §6.4 truth table

A, X, IG = Verdict.ALOG, Verdict.XLOG, Verdict.IGNORE


@pytest.mark.parametrize(
    ("patterns", "omits", "exclusion", "expected"),
    [
        # accept (empty list) / not rejected
        ([], [], False, A),
        ([], [], True, A),
        # accept (a pattern matches) / not rejected
        (["DEPTH*"], ["*_STATUS"], False, A),
        (["DEPTH*"], ["*_STATUS"], True, A),
        # accept / rejected
        ([], ["DEP?H"], False, IG),
        ([], ["DEP?H"], True, X),
        (["D*"], ["*TH"], False, IG),
        (["D*"], ["*TH"], True, X),
        # not accepted / not rejected: the xlog takes it too
        (["NAV_*"], [], False, IG),
        (["NAV_*"], [], True, X),
        # not accepted / rejected
        (["NAV_*"], ["DEPTH"], False, IG),
        (["NAV_*"], ["DEPTH"], True, X),
    ],
)
def test_truth_table_for_a_discovered_name(
    patterns: list[str], omits: list[str], exclusion: bool, expected: Verdict
) -> None:
    classifier = WildcardClassifier(["NAV_X"], patterns, omits, exclusion)
    assert classifier.classify("DEPTH") is expected


def spec_verdict(
    name: str,
    log_vars: list[str],
    patterns: list[str],
    omits: list[str],
    exclusion: bool,
    wildcard: bool,
) -> Verdict:
    """§6.4 written out independently of the implementation."""
    if name in log_vars or name in ("MOOS_DEBUG", "MOOS_SYSTEM"):
        return A
    if not wildcard:
        return IG
    accept = not patterns or any(moos_wild_cmp(p, name) for p in patterns)
    reject = name == "MISSION_FILE" or any(moos_wild_cmp(o, name) for o in omits)
    if accept and not reject:
        return A
    return X if exclusion else IG


TABLE_NAMES = ["NAV_X", "MOOS_DEBUG", "MOOS_SYSTEM", "MISSION_FILE", "DEPTH", "moos_debug"]


@pytest.mark.parametrize("name", TABLE_NAMES)
@pytest.mark.parametrize("explicit", [False, True])
@pytest.mark.parametrize("patterns", ["none", "match", "miss"])
@pytest.mark.parametrize("omits", ["none", "match", "miss"])
@pytest.mark.parametrize("exclusion", [False, True])
@pytest.mark.parametrize("wildcard", [False, True])
def test_truth_table_every_combination(
    name: str, explicit: bool, patterns: str, omits: str, exclusion: bool, wildcard: bool
) -> None:
    log_vars = [name] if explicit else ["OTHER"]
    pattern_list = {"none": [], "match": [name[:2] + "*"], "miss": ["ZZ*"]}[patterns]
    omit_list = {"none": [], "match": ["?" + name[1:]], "miss": ["*QQ"]}[omits]
    classifier = WildcardClassifier(
        log_vars, pattern_list, omit_list, exclusion, wildcard_enabled=wildcard
    )
    expected = spec_verdict(name, log_vars, pattern_list, omit_list, exclusion, wildcard)
    assert classifier.classify(name) is expected
    assert classifier.classify(name) is expected  # cached
    # Spot the rules the table stands for.
    if explicit or name in ALWAYS_LOGGED:
        assert expected is A
    if name == "MISSION_FILE" and not explicit:
        assert expected is not A


@settings(max_examples=300)
@given(
    st.lists(names, max_size=3),
    st.lists(globs, max_size=3),
    st.lists(globs, max_size=3),
    st.booleans(),
    st.booleans(),
    names,
)
def test_truth_table_random(
    log_vars: list[str],
    patterns: list[str],
    omits: list[str],
    exclusion: bool,
    wildcard: bool,
    name: str,
) -> None:
    classifier = WildcardClassifier(log_vars, patterns, omits, exclusion, wildcard_enabled=wildcard)
    expected = spec_verdict(name, log_vars, patterns, omits, exclusion, wildcard)
    assert classifier.classify(name) is expected
    if expected is not IG:
        # A subscriber on the classifier's key suffixes sees the name.
        assert any(key(c).includes(key(name_to_chunk(name))) for c in classifier.key_suffixes())


def test_explicit_vars_are_never_omitted() -> None:
    classifier = WildcardClassifier(["NAV_X", "MISSION_FILE"], ["ZZ*"], ["*"], False)
    assert classifier.classify("NAV_X") is A
    assert classifier.classify("MISSION_FILE") is A
    assert classifier.classify("MOOS_DEBUG") is A
    assert classifier.classify("MOOS_SYSTEM") is A
    assert classifier.classify("DEPTH") is IG
    assert classifier.omit_patterns == ("*", "MISSION_FILE")


def test_wildcard_off_logs_only_explicit_and_log_requests() -> None:
    classifier = WildcardClassifier(["NAV_X"], [], [], True, wildcard_enabled=False)
    assert classifier.classify("NAV_X") is A
    assert classifier.classify("MOOS_DEBUG") is A
    assert classifier.classify("DEPTH") is IG
    assert classifier.add_log_var("DEPTH")
    assert classifier.classify("DEPTH") is A  # the cached IGNORE was replaced
    assert not classifier.add_log_var("DEPTH")  # already logged: pLogger's failure case
    assert not classifier.add_log_var("MOOS_DEBUG")
    assert classifier.log_vars == ("NAV_X", "DEPTH")
    assert classifier.key_suffixes() == ["MOOS_DEBUG", "MOOS_SYSTEM", "NAV_X", "DEPTH"]


def test_add_log_var_overrides_omit() -> None:
    classifier = WildcardClassifier([], [], ["*_STATUS"], True)
    assert classifier.classify("HELM_STATUS") is X
    classifier.add_log_var("HELM_STATUS")
    assert classifier.classify("HELM_STATUS") is A


def test_cache_is_bounded() -> None:
    classifier = WildcardClassifier([], ["A*"], [], False, cache_size=8)
    for i in range(100):
        assert classifier.classify(f"A{i}") is A
        assert classifier.classify(f"B{i}") is IG
    assert len(classifier._cache) <= 8
    assert classifier.classify("A0") is A


def test_key_suffixes() -> None:
    assert WildcardClassifier(["NAV_X"], [], [], False).key_suffixes() == ["*"]
    assert WildcardClassifier(["NAV_X"], ["D*"], [], True).key_suffixes() == ["*"]
    classifier = WildcardClassifier(["NAV_X", "DEPTH"], ["D*", "*_STATUS"], [], False)
    assert classifier.key_suffixes() == ["D$*", "$*_STATUS", "MOOS_DEBUG", "MOOS_SYSTEM", "NAV_X"]
