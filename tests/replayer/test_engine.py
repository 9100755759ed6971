"""The player with a fake clock: pacing, rate, pause, step, seek, loop, choke, filters, merge."""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

import pytest
from replay_support import Line, MakeSession

from fleetlog.errors import ReplayError
from fleetlog.replayer.clock import FakeClock
from fleetlog.replayer.control import Pause, Resume, Seek, SetRate, Step, Stop, Toggle
from fleetlog.replayer.engine import Player
from fleetlog.replayer.filters import FilterSpec
from fleetlog.replayer.inputs import ReplayInput, open_inputs
from fleetlog.replayer.options import PlayOptions
from fleetlog.replayer.report import State
from fleetlog.wire.message import MoosMessage

LOGSTART = 1_800_000_000.0


@dataclass(frozen=True)
class Sent:
    """One published message and the fake time it went out."""

    at: float
    vehicle: str
    message: MoosMessage


class Harness:
    """A player over fake time that records what it publishes."""

    def __init__(
        self, inputs: list[ReplayInput], options: PlayOptions | None = None, start: float = 0.0
    ) -> None:
        self.clock = FakeClock(start=start)
        self.sent: list[Sent] = []
        self.player = Player(inputs, self._publish, self.clock, options)

    def _publish(self, vehicle: str, message: MoosMessage) -> None:
        self.sent.append(Sent(self.clock.now(), vehicle, message))

    def at(self, when: float, command: object) -> None:
        """Submit a command at fake time ``when``."""
        self.clock.call_at(when, lambda: self.player.submit(command))  # type: ignore[arg-type]

    def data(self) -> list[Sent]:
        """What was published, without PLAYBACK_DB_TIME."""
        return [s for s in self.sent if s.message.name != "PLAYBACK_DB_TIME"]

    def times(self) -> list[float]:
        return [round(s.at, 6) for s in self.data()]

    def names(self) -> list[str]:
        return [s.message.name for s in self.data()]


@pytest.fixture
def opened() -> Iterator[list[list[ReplayInput]]]:
    """Inputs opened by a test, closed afterwards."""
    holder: list[list[ReplayInput]] = []
    yield holder
    for inputs in holder:
        for item in inputs:
            item.close()


def open_all(
    opened: list[list[ReplayInput]], paths: Sequence[Path], vehicles: Sequence[str] = ()
) -> list[ReplayInput]:
    inputs = open_inputs(paths, vehicles)
    opened.append(inputs)
    return inputs


STEADY = [
    Line(1.0, "A", "pA", 1.0),
    Line(1.5, "B", "pB", "b"),
    Line(3.0, "C", "pC", 3.0),
    Line(3.25, "D", "pA", "d"),
]


# -- pacing


def test_entries_are_published_at_their_offsets(make_session: MakeSession, opened: list) -> None:
    h = Harness(open_all(opened, [make_session(STEADY, vehicle=None)], ["alpha"]))
    summary = h.player.run()
    # Playback starts at the first entry, so offsets count from 1.0.
    assert h.times() == [0.0, 0.5, 2.0, 2.25]
    assert h.names() == ["A", "B", "C", "D"]
    assert summary.state is State.FINISHED
    assert summary.published == 4
    # The clock slept exactly until each entry was due.
    assert [w for w in h.clock.waits if w is not None] == [0.5, 2.0, 2.25]


@pytest.mark.parametrize(
    ("rate", "expected"), [(2.0, [0.0, 0.25, 1.0, 1.125]), (0.5, [0, 1, 4, 4.5])]
)
def test_rate_scales_the_schedule(
    make_session: MakeSession, opened: list, rate: float, expected: list[float]
) -> None:
    h = Harness(
        open_all(opened, [make_session(STEADY, vehicle=None)], ["alpha"]), PlayOptions(rate=rate)
    )
    h.player.run()
    assert h.times() == [pytest.approx(t) for t in expected]


def test_fast_never_waits(make_session: MakeSession, opened: list) -> None:
    h = Harness(
        open_all(opened, [make_session(STEADY, vehicle=None)], ["alpha"]), PlayOptions(rate=None)
    )
    summary = h.player.run()
    assert h.times() == [0.0] * 4
    assert h.clock.waits == []
    assert summary.published == 4


def test_rate_change_reanchors_at_the_position(make_session: MakeSession, opened: list) -> None:
    h = Harness(open_all(opened, [make_session(STEADY, vehicle=None)], ["alpha"]))
    h.at(1.0, SetRate(2.0))  # position 2.0 at fake time 1.0; C (3.0) is 1 s of log away
    h.player.run()
    assert h.times() == [0.0, 0.5, 1.5, 1.625]


def test_rate_ladder_up_to_fast(make_session: MakeSession, opened: list) -> None:
    h = Harness(
        open_all(opened, [make_session(STEADY, vehicle=None)], ["alpha"]), PlayOptions(rate=100.0)
    )
    h.at(0.001, SetRate(steps=1))  # past 100 is as fast as possible
    h.player.run()
    assert h.times() == [0.0, 0.001, 0.001, 0.001]
    assert h.player.status().rate is None


# -- pause, resume, step, seek, stop


def test_pause_holds_the_position_and_resume_continues(
    make_session: MakeSession, opened: list
) -> None:
    h = Harness(open_all(opened, [make_session(STEADY, vehicle=None)], ["alpha"]))
    h.at(0.7, Pause())  # position 1.7
    h.at(5.0, Resume())
    h.player.run()
    # C at 3.0 is 1.3 s of log after the pause position: due 5.0 + 1.3.
    assert h.times() == [0.0, 0.5, 6.3, 6.55]


def test_toggle_and_status_while_paused(make_session: MakeSession, opened: list) -> None:
    h = Harness(open_all(opened, [make_session(STEADY, vehicle=None)], ["alpha"]))
    seen = []
    h.at(0.7, Toggle())
    h.clock.call_at(2.0, lambda: seen.append(h.player.status()))
    h.at(3.0, Toggle())
    h.player.run()
    assert seen[0].state is State.PAUSED
    assert seen[0].offset == pytest.approx(1.7)
    assert seen[0].published == 2
    assert h.times() == [0.0, 0.5, 4.3, 4.55]


def test_paused_start_and_steps(make_session: MakeSession, opened: list) -> None:
    h = Harness(
        open_all(opened, [make_session(STEADY, vehicle=None)], ["alpha"]), PlayOptions(paused=True)
    )
    h.at(1.0, Step())  # A
    h.at(2.0, Step(2))  # B, C
    h.at(3.0, Stop())
    summary = h.player.run()
    assert h.times() == [1.0, 2.0, 2.0]
    assert h.names() == ["A", "B", "C"]
    assert summary.state is State.STOPPED
    assert h.player.status().offset == pytest.approx(3.0)


def test_step_seconds_publishes_the_next_span(make_session: MakeSession, opened: list) -> None:
    h = Harness(
        open_all(opened, [make_session(STEADY, vehicle=None)], ["alpha"]), PlayOptions(paused=True)
    )
    h.at(1.0, Step(seconds=2.0))  # (1.0 ... 3.0]: A is at the position itself, so A, B, C
    h.at(2.0, Resume())
    h.player.run()
    assert h.names() == ["A", "B", "C", "D"]
    # After the step the position is 3.0; D (3.25) is due 0.25 s after the resume.
    assert h.times() == [1.0, 1.0, 1.0, 2.25]


def test_step_while_playing_pauses(make_session: MakeSession, opened: list) -> None:
    h = Harness(open_all(opened, [make_session(STEADY, vehicle=None)], ["alpha"]))
    h.at(0.2, Step())  # B at once, then paused
    h.at(10.0, Stop())
    h.player.run()
    assert h.names() == ["A", "B"]
    assert h.times() == [0.0, 0.2]


def test_seek_forward_skips_without_publishing(make_session: MakeSession, opened: list) -> None:
    h = Harness(open_all(opened, [make_session(STEADY, vehicle=None)], ["alpha"]))
    h.at(0.1, Seek(to=3.1))
    h.player.run()
    assert h.names() == ["A", "D"]
    assert h.times() == [0.0, pytest.approx(0.25)]


def test_seek_back_replays_again(make_session: MakeSession, opened: list) -> None:
    h = Harness(open_all(opened, [make_session(STEADY, vehicle=None)], ["alpha"]))
    h.at(2.1, Seek(by=-2.0))  # from 3.1 back to 1.1
    h.player.run()
    assert h.names() == ["A", "B", "C", "B", "C", "D"]
    assert h.times()[3:] == [pytest.approx(2.5), pytest.approx(4.0), pytest.approx(4.25)]


def test_seek_is_clamped_to_the_replay(make_session: MakeSession, opened: list) -> None:
    h = Harness(
        open_all(opened, [make_session(STEADY, vehicle=None)], ["alpha"]), PlayOptions(paused=True)
    )
    results = []
    h.clock.call_at(1.0, lambda: results.append(h.player.submit(Seek(to=-50.0))))
    h.clock.call_at(2.0, lambda: results.append(h.player.submit(Seek(to=500.0))))
    h.at(3.0, Stop())
    h.player.run()
    assert results[0].result().offset == pytest.approx(1.0)  # the first entry
    assert results[1].result().offset == pytest.approx(3.25)  # the end (a plain alog's tail)


def test_commands_after_the_end_fail(make_session: MakeSession, opened: list) -> None:
    h = Harness(
        open_all(opened, [make_session(STEADY, vehicle=None)], ["alpha"]), PlayOptions(rate=None)
    )
    h.player.run()
    with pytest.raises(ReplayError, match="ended"):
        h.player.submit(Pause()).result()


def test_loop_starts_again(make_session: MakeSession, opened: list) -> None:
    h = Harness(
        open_all(opened, [make_session(STEADY, vehicle=None)], ["alpha"]), PlayOptions(loop=True)
    )
    h.at(4.4, Stop())
    summary = h.player.run()
    assert h.names() == ["A", "B", "C", "D", "A", "B", "C"]
    assert h.times() == [0.0, 0.5, 2.0, 2.25, 2.25, 2.75, 4.25]
    assert summary.loops == 1


def test_from_and_to(make_session: MakeSession, opened: list) -> None:
    h = Harness(
        open_all(opened, [make_session(STEADY, vehicle=None)], ["alpha"]),
        PlayOptions(start=1.2, stop=3.0),
    )
    summary = h.player.run()
    assert h.names() == ["B", "C"]
    assert h.times() == [pytest.approx(0.3), pytest.approx(1.8)]
    assert h.player.status().end == pytest.approx(3.0)
    assert summary.state is State.FINISHED


def test_stop_before_start_is_refused(make_session: MakeSession, opened: list) -> None:
    with pytest.raises(ReplayError, match="before --from"):
        Harness(open_all(opened, [make_session(STEADY)]), PlayOptions(start=3.0, stop=1.0))


# -- PLAYBACK_CHOKE


def test_choke_holds_playback_until_a_fresh_heartbeat(
    make_session: MakeSession, opened: list
) -> None:
    lines = [Line(1.0 + 0.5 * i, f"V{i}", "p", float(i)) for i in range(12)]  # 1.0 ... 6.5
    h = Harness(open_all(opened, [make_session(lines, vehicle=None)], ["alpha"]))
    wall = h.clock.wall
    h.clock.call_at(0.0, lambda: h.player.heartbeat(wall()))  # one heartbeat, then silence
    states = []
    h.clock.call_at(2.5, lambda: states.append(h.player.status()))
    for beat in range(10, 17):  # the client catches up, and keeps its heartbeat going
        h.clock.call_at(float(beat), lambda: h.player.heartbeat(wall()))
    h.player.run()
    times = h.times()
    # Entries up to 2.0 s (heartbeat age 2.0, not more) go out on time; then nothing until
    # the fresh heartbeat at 10.0, and the rest keeps its spacing from there.
    assert times[:5] == [0.0, 0.5, 1.0, 1.5, 2.0]
    assert times[5] == pytest.approx(10.5)
    assert times[-1] == pytest.approx(10.5 + 3.0)
    assert states[0].state is State.WAITING
    assert states[0].offset == pytest.approx(3.0 + 1e-6, abs=1e-5)


def test_seek_resets_the_choke(make_session: MakeSession, opened: list) -> None:
    lines = [Line(1.0 + 0.5 * i, f"V{i}", "p", float(i)) for i in range(12)]
    h = Harness(open_all(opened, [make_session(lines, vehicle=None)], ["alpha"]))
    wall = h.clock.wall
    h.clock.call_at(0.0, lambda: h.player.heartbeat(wall()))
    h.at(5.0, Seek(to=5.0))  # choked since 2.0; the seek forgets the heartbeat
    h.player.run()
    assert h.names()[5:] == ["V8", "V9", "V10", "V11"]
    assert h.times()[5:] == [5.0, 5.5, 6.0, 6.5]


# -- filters


MIXED = [
    Line(1.0, "NAV_X", "pNav", 1.0),
    Line(1.1, "DEPLOY", "pHelmIvP:HELM_VAR_INIT", "true"),
    Line(1.2, "VIEW", "pMarineViewer@shoreside", "x"),
    Line(1.3, "NAV_Y", "pNav", 2.0),
    Line(1.4, "DESIRED_SPEED", "pHelmIvP", 1.5),
]


@pytest.mark.parametrize(
    ("spec", "expected"),
    [
        (FilterSpec(exclude_sources=("pHelmIvP",)), ["NAV_X", "VIEW", "NAV_Y"]),
        (
            FilterSpec(exclude_sources=("pHelmIvP:HELM_VAR_INIT",)),
            ["NAV_X", "VIEW", "NAV_Y", "DESIRED_SPEED"],
        ),
        (FilterSpec(include_sources=("p*@shoreside",)), ["VIEW"]),
        (FilterSpec(include_sources=("pMarineViewer",)), ["VIEW"]),
        (
            FilterSpec(include_sources=("pN?v", "pHelm*"), exclude_sources=("*:*",)),
            ["NAV_X", "NAV_Y", "DESIRED_SPEED"],
        ),
        (FilterSpec(include_vars=("NAV_*",)), ["NAV_X", "NAV_Y"]),
        (FilterSpec(exclude_vars=("NAV_?", "VIEW")), ["DEPLOY", "DESIRED_SPEED"]),
    ],
)
def test_filters(
    make_session: MakeSession, opened: list, spec: FilterSpec, expected: list[str]
) -> None:
    h = Harness(
        open_all(opened, [make_session(MIXED, vehicle=None)], ["alpha"]),
        PlayOptions(rate=None, filters=spec),
    )
    summary = h.player.run()
    assert h.names() == expected
    assert summary.filtered == len(MIXED) - len(expected)
    assert summary.vehicles["alpha"].filtered == len(MIXED) - len(expected)


def test_filtered_entries_are_not_waited_for(make_session: MakeSession, opened: list) -> None:
    h = Harness(
        open_all(opened, [make_session(STEADY, vehicle=None)], ["alpha"]),
        PlayOptions(filters=FilterSpec(exclude_vars=("C",))),
    )
    h.player.run()
    assert h.times() == [0.0, 0.5, 2.25]
    assert 2.0 not in h.clock.waits


# -- what is published


def test_messages_keep_source_aux_community_and_original_time(
    make_session: MakeSession, opened: list
) -> None:
    h = Harness(
        open_all(opened, [make_session(MIXED, vehicle=None, logstart=LOGSTART)], ["alpha"]),
        PlayOptions(rate=None),
    )
    h.player.run()
    sent = {s.message.name: s.message for s in h.data()}
    deploy = sent["DEPLOY"]
    assert (deploy.source, deploy.aux, deploy.community) == ("pHelmIvP", "HELM_VAR_INIT", "")
    view = sent["VIEW"]
    assert (view.source, view.aux, view.community) == ("pMarineViewer", "", "shoreside")
    assert sent["NAV_X"].original_time == pytest.approx(LOGSTART + 1.0)
    # The message time is the replay clock's wall time, as uPlayBack's MOOSTime().
    assert sent["NAV_X"].time == h.clock.wall()


def test_values_survive_exactly(make_session: MakeSession, opened: list) -> None:
    values: list[float | str | bytes] = [
        -0.0,
        1e-7,
        123456789.123456,
        "  two leading spaces",
        "",
        "carriage\rreturn",
        "line1\nline2\n  line3",
        "trailing  ",
        "0.5",
        b"\x00\x01binary\n\xff",
    ]
    lines = [Line(1.0 + i * 0.1, f"V{i}", "p", v) for i, v in enumerate(values)]
    h = Harness(
        open_all(opened, [make_session(lines, vehicle=None)], ["alpha"]), PlayOptions(rate=None)
    )
    h.player.run()
    got = [s.message.value for s in h.data()]
    # Doubles come back as pLogger wrote them (5 decimals); everything else byte for byte.
    assert got == [-0.0, 0.0, 123456789.12346, *values[3:]]
    assert isinstance(got[0], float)
    assert str(got[0]) == "-0.0"
    assert isinstance(got[8], str)  # "0.5" unpadded was a string, and stays one


def test_unreadable_binary_is_counted_not_fatal(make_session: MakeSession, opened: list) -> None:
    session = make_session([Line(1.0, "BIN", "p", b"abc"), Line(2.0, "X", "p", 1.0)], vehicle=None)
    next(session.glob("*.blog")).write_bytes(b"")
    h = Harness(open_all(opened, [session], ["alpha"]), PlayOptions(rate=None))
    summary = h.player.run()
    assert h.names() == ["X"]
    assert summary.unplayable == 1
    assert "Offset=" in summary.errors[0]


def test_db_time_opens_each_tick_per_vehicle(make_session: MakeSession, opened: list) -> None:
    lines = [Line(1.0, "A", "p", 1.0), Line(1.004, "B", "p", 2.0), Line(1.5, "C", "p", 3.0)]
    h = Harness(
        open_all(opened, [make_session(lines, vehicle=None, logstart=LOGSTART)], ["alpha"]),
        start=100.0,
    )
    h.player.run()
    names = [s.message.name for s in h.sent]
    # A and B share a 10 ms tick: one marker before them; C opens a new tick.
    assert names == ["PLAYBACK_DB_TIME", "A", "B", "PLAYBACK_DB_TIME", "C"]
    first, second = h.sent[0].message, h.sent[3].message
    assert first.source == "uPlayback"
    assert isinstance(first.value, float)
    # The marker carries the log time at the end of its tick (absolute).
    assert LOGSTART + 1.004 <= first.value <= LOGSTART + 1.0 + 0.01 + 1e-9
    assert LOGSTART + 1.5 <= second.value <= LOGSTART + 1.51 + 1e-9
    assert first.original_time is None


def test_db_time_can_be_turned_off(make_session: MakeSession, opened: list) -> None:
    h = Harness(
        open_all(opened, [make_session(STEADY, vehicle=None)], ["alpha"]),
        PlayOptions(rate=None, db_time=False),
    )
    h.player.run()
    assert [s.message.name for s in h.sent] == ["A", "B", "C", "D"]


# -- order, duplicates, several vehicles


def test_out_of_order_lines_play_in_time_order(make_session: MakeSession, opened: list) -> None:
    lines = [
        Line(1.0, "A", "p", 1.0),
        Line(3.0, "C", "p", 3.0),
        Line(2.0, "B", "p", 2.0),  # a later mail batch with an older time
        Line(4.0, "D", "p", 4.0),
    ]
    h = Harness(open_all(opened, [make_session(lines, vehicle=None)], ["alpha"]))
    summary = h.player.run()
    assert h.names() == ["A", "B", "C", "D"]
    assert h.times() == [0.0, 1.0, 2.0, 3.0]
    assert summary.late == 0


def test_lines_beyond_the_window_play_late(make_session: MakeSession, opened: list) -> None:
    lines = [Line(1.0 + i, f"V{i}", "p", float(i)) for i in range(5)]
    lines.append(Line(1.5, "OLD", "p", 9.0))  # five lines late, the window holds two
    h = Harness(
        open_all(opened, [make_session(lines, vehicle=None)], ["alpha"]),
        PlayOptions(rate=None, window=2),
    )
    summary = h.player.run()
    assert h.names() == ["V0", "V1", "V2", "OLD", "V3", "V4"]
    assert summary.late == 1


def test_duplicates_and_negative_times_are_dropped(make_session: MakeSession, opened: list) -> None:
    lines = [
        Line(-7.479, "STALE", "p", 1.0),  # re-delivered from before LOGSTART
        Line(1.0, "A", "p", 1.0),
        Line(1.2, "B", "p", "b"),
        Line(1.5, "C", "p", 3.0),
        Line(1.0, "A", "p", 1.0),  # re-delivery after a re-registration
        Line(1.2, "B", "p", "b"),
        Line(1.2, "B", "p", "other"),  # same time, another value: not a duplicate
    ]
    session = make_session(lines, vehicle=None)
    h = Harness(open_all(opened, [session], ["alpha"]), PlayOptions(rate=None))
    summary = h.player.run()
    assert h.names() == ["A", "B", "B", "C"]
    assert summary.duplicates == 2
    assert summary.before_logstart == 1
    keep = Harness(open_all(opened, [session], ["alpha"]), PlayOptions(rate=None, dedupe=False))
    keep.player.run()
    assert keep.names() == ["A", "A", "B", "B", "B", "C"]


def test_vehicles_merge_on_one_clock(make_session: MakeSession, opened: list) -> None:
    alpha = make_session(
        [Line(1.0, "A1", "p", 1.0), Line(3.0, "A2", "p", 2.0)], vehicle="alpha", logstart=LOGSTART
    )
    bravo = make_session(
        [Line(0.5, "B1", "p", 1.0), Line(1.2, "B2", "p", 2.0)],
        vehicle=None,
        moos_community="bravo",
        logstart=LOGSTART + 1.0,  # started a second later
    )
    h = Harness(open_all(opened, [alpha, bravo]), PlayOptions(prefix="sim_"))
    summary = h.player.run()
    data = h.data()
    assert [(s.vehicle, s.message.name) for s in data] == [
        ("sim_alpha", "DB_TIME"),
        ("sim_alpha", "A1"),
        ("sim_bravo", "B1"),
        ("sim_bravo", "B2"),
        ("sim_alpha", "A2"),
    ]
    assert [round(s.at, 6) for s in data] == [0.0, 1.0, 1.5, 2.2, 3.0]
    originals = [s.message.original_time for s in data]
    assert originals == sorted(originals)  # type: ignore[type-var]
    assert set(summary.vehicles) == {"sim_alpha", "sim_bravo"}
    assert summary.inputs[1][1:4] == ("bravo", "sim_bravo", "._moos")
    assert "  input " + str(bravo) + ": vehicle bravo (from ._moos), published as sim_bravo" in (
        summary.lines()
    )


def test_status_reports_progress(make_session: MakeSession, opened: list) -> None:
    h = Harness(open_all(opened, [make_session(STEADY, vehicle=None)], ["alpha"]))
    seen = []
    h.clock.call_at(1.125, lambda: seen.append(h.player.status()))
    h.player.run()
    status = seen[0]
    assert status.state is State.PLAYING
    assert status.begin == pytest.approx(1.0)
    assert status.end == pytest.approx(3.25)
    assert status.offset == pytest.approx(2.125)
    assert status.fraction == pytest.approx(0.5)
    assert status.to_dict()["rate"] == 1.0
    assert h.player.status().state is State.FINISHED


def test_idle_hooks_run_in_the_gaps_and_while_paused(
    make_session: MakeSession, opened: list
) -> None:
    h = Harness(open_all(opened, [make_session(STEADY, vehicle=None)], ["alpha"]))
    calls: list[float] = []
    h.player.idle_hooks.append(lambda: calls.append(round(h.clock.now(), 6)))
    h.player.run()
    # Every 0.25 s while waiting, never in the way of an entry: the schedule is unchanged.
    assert calls == [0.0, 0.25, 0.5, 0.75, 1.0, 1.25, 1.5, 1.75, 2.0]
    assert h.times() == [0.0, 0.5, 2.0, 2.25]
    paused = Harness(open_all(opened, [make_session(STEADY, vehicle=None)], ["alpha"]))
    calls.clear()
    paused.player.idle_hooks.append(lambda: calls.append(round(paused.clock.now(), 6)))
    paused.at(0.6, Pause())
    paused.at(1.4, Resume())
    paused.player.run()
    assert [t for t in calls if 0.6 < t < 1.4] == [0.75, 1.0, 1.25]
