"""The player (uPlayBack over Zenoh): alogs and sessions replayed on one clock.

No Zenoh here: :class:`Player` publishes through a function it is given and paces itself by
a :class:`~fleetlog.replayer.clock.Clock`, so its logic is tested with a fake clock. The
Zenoh side (publishing, PLAYBACK_CHOKE, the control queryable, the status publication) is
:mod:`fleetlog.transport.replay`; the command is ``fleetlog replay``.
"""

from fleetlog.replayer.clock import FakeClock, RealClock
from fleetlog.replayer.engine import Player
from fleetlog.replayer.filters import FilterSpec
from fleetlog.replayer.inputs import ReplayInput, open_inputs
from fleetlog.replayer.options import PlayOptions
from fleetlog.replayer.report import State, Status, Summary

__all__ = [
    "FakeClock",
    "FilterSpec",
    "PlayOptions",
    "Player",
    "RealClock",
    "ReplayInput",
    "State",
    "Status",
    "Summary",
    "open_inputs",
]
