"""The states the appliance reports, in one table: each one's Modbus code, the words a technician reads,
whether a measurement is running in it and whether the angle sensor is being read in it. (Here, not with the
sequencer: reading it must not load the sequencer and the science it drives; a test holds it to
``firmware_host.State`` and ``firmware_host.BUSY``.) The web page's script reads it as served with the page
(``vocabulary``)."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass


@dataclass(frozen=True)
class StateInfo:
    """What the appliance says of a state: its code in Modbus register ``state``, the words a technician
    reads on the web page, whether a measurement is running (a request is refused as busy) and whether the
    angle sensor is being read in it."""

    code: int
    words: str
    busy: bool = False
    capturing: bool = False


#: every state the appliance reports, the sequencer's (``firmware_host.State``) and the daemon's own
#: (STARTING, STOPPING): the one table the Modbus registers and the web page read
STATES: dict[str, StateInfo] = {
    "STARTING": StateInfo(0, "the appliance is starting"),
    "IDLE": StateInfo(1, "no measurement running"),
    "ARMED": StateInfo(2, "recording the pendulum at rest before the release", busy=True, capturing=True),
    "RELEASING": StateInfo(3, "solenoid pulse: releasing the pendulum", busy=True, capturing=True),
    "CAPTURING": StateInfo(4, "the pendulum swings freely; recording", busy=True, capturing=True),
    "IDENTIFYING": StateInfo(5, "identifying the equation of motion", busy=True),
    "PUBLISHING": StateInfo(6, "storing and publishing the result", busy=True),
    "FAULT": StateInfo(7, "fault: acknowledge it once the cause is fixed"),
    "ABORTED": StateInfo(8, "the measurement was abandoned"),
    "STOPPING": StateInfo(9, "the appliance is stopping"),
}


def vocabulary() -> dict[str, dict[str, object]]:
    """The table, JSON-ready (``{name: {code, words, busy, capturing}}``): what the web page's script reads."""
    return {name: dataclasses.asdict(info) for name, info in STATES.items()}
