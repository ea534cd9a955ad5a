"""What the page says about states and quality flags, in words a technician reads."""

from __future__ import annotations

from measurement.flags import describe

#: sequencer state → what is happening
STATE_WORDS: dict[str, str] = {
    "STARTING": "the appliance is starting",
    "IDLE": "ready: press Measure (or the push button)",
    "ARMED": "recording the pendulum at rest before the release",
    "RELEASING": "solenoid pulse: releasing the pendulum",
    "CAPTURING": "the pendulum swings freely; recording",
    "IDENTIFYING": "identifying the equation of motion",
    "PUBLISHING": "storing and publishing the result",
    "FAULT": "fault: acknowledge it once the cause is fixed",
    "ABORTED": "the measurement was abandoned",
    "STOPPING": "the appliance is stopping",
}


def flag_words(flags) -> list[tuple[str, str]]:
    """(flag, its meaning) for each flag; the meanings are the one table in ``measurement.flags``."""
    return [(f, describe(f)) for f in flags or ()]
