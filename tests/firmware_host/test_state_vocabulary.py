"""One table of the states the appliance reports: every sequencer state is in it, codes are distinct,
and the registers and the web page read it."""

import json
import re
from pathlib import Path

from firmware_host.states import BUSY, State
from service.publish.modbus import registers as R
from service.publish.words import STATE_WORDS
from service.states import STATES


def test_every_sequencer_state_has_a_code_and_words():
    assert {s.value for s in State} <= set(STATES)
    assert len({s.code for s in STATES.values()}) == len(STATES)
    assert all(s.words for s in STATES.values())


def test_the_busy_group_is_the_sequencers():
    assert {name for name, s in STATES.items() if s.busy} == {s.value for s in BUSY}


def test_the_page_script_and_style_name_only_states_of_the_table():
    static = Path(__file__).resolve().parents[2] / "service" / "publish" / "web" / "static"
    js = (static / "moi.js").read_text(encoding="utf-8")
    css = (static / "moi.css").read_text(encoding="utf-8")
    named = set(re.findall(r'state(?:\.state)? === "([A-Z_]+)"|previous === "([A-Z_]+)"', js))
    names = {n for pair in named for n in pair if n} | set(re.findall(r"\.state-([A-Z_]+)", css))
    assert names and names <= set(STATES), names - set(STATES)
    # a group of states (the busy ones) is read from the table served with the page, not listed in the script
    state = re.compile('"(?:' + "|".join(STATES) + ')"')
    assert all(len(state.findall(line)) <= 2 for line in js.splitlines())


def test_the_page_serves_the_table_as_json():
    from service.states import vocabulary

    served = json.loads(json.dumps(vocabulary()))
    assert served["CAPTURING"] == {"code": 4, "words": STATES["CAPTURING"].words, "busy": True, "capturing": True}
    assert set(served) == set(STATES)


def test_the_registers_and_the_page_read_the_table():
    assert {name: s.code for name, s in STATES.items()} == R.STATE_CODES
    assert {name: s.words for name, s in STATES.items()} == STATE_WORDS


def test_an_event_says_when_a_measurement_ends_and_when_it_is_published():
    from firmware_host.states import Event

    def ev(new: State, old: State, measurement=None) -> Event:
        return Event(1, 0.0, new, old, "", None, measurement)

    assert ev(State.IDLE, State.PUBLISHING).ends_measurement and ev(State.FAULT, State.CAPTURING).ends_measurement
    assert not ev(State.IDLE, State.IDLE).ends_measurement and not ev(State.ARMED, State.IDLE).ends_measurement
    assert ev(State.PUBLISHING, State.IDENTIFYING, measurement=object()).publishes
    assert not ev(State.PUBLISHING, State.IDENTIFYING).publishes and not ev(State.IDLE, State.PUBLISHING).publishes
