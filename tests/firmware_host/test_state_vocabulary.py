"""One table of the states the appliance reports: every sequencer state is in it, codes are distinct,
and the registers and the web page read it."""

from firmware_host.states import State
from service.states import STATES
from service.publish.modbus import registers as R
from service.publish.web.words import STATE_WORDS


def test_every_sequencer_state_has_a_code_and_words():
    assert {s.value for s in State} <= set(STATES)
    assert len({s.code for s in STATES.values()}) == len(STATES)
    assert all(s.words for s in STATES.values())


def test_the_registers_and_the_page_read_the_table():
    assert R.STATE_CODES == {name: s.code for name, s in STATES.items()}
    assert STATE_WORDS == {name: s.words for name, s in STATES.items()}


def test_an_event_says_when_a_measurement_ends_and_when_it_is_published():
    from firmware_host.states import Event

    def ev(new: State, old: State, measurement=None) -> Event:
        return Event(1, 0.0, new, old, "", None, measurement)

    assert ev(State.IDLE, State.PUBLISHING).ends_measurement and ev(State.FAULT, State.CAPTURING).ends_measurement
    assert not ev(State.IDLE, State.IDLE).ends_measurement and not ev(State.ARMED, State.IDLE).ends_measurement
    assert ev(State.PUBLISHING, State.IDENTIFYING, measurement=object()).publishes
    assert not ev(State.PUBLISHING, State.IDENTIFYING).publishes and not ev(State.IDLE, State.PUBLISHING).publishes
