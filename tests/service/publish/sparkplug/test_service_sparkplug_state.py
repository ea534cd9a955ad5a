"""The primary host's STATE read as untrusted input, and Rebirth requests at most one birth per interval (no broker)."""

from __future__ import annotations

import json

import pytest

from service.errors import HostStateRefused
from service.publish.sparkplug.host_state import HostState, read_state
from service.publish.sparkplug.rebirth import BirthLimit

NOW = 1_780_000_000_000  # ms
TOLERANCE = 300_000


@pytest.mark.parametrize("raw", [
    b'{"online": true, "timestamp": 1e30}', b'{"online": false, "timestamp": 1e30}',
    b'{"online": true, "timestamp": Infinity}', b'{"online": true, "timestamp": -Infinity}',
    b'{"online": true, "timestamp": NaN}', b'{"online": true, "timestamp": 1e400}',
    b'{"online": true, "timestamp": 1' + b"0" * 400 + b"}", b'{"online": true, "timestamp": 1.5}',
    b'{"online": true, "timestamp": -1}', b'{"online": true, "timestamp": true}', b'{"online": true, "timestamp": "1"}',
    b'{"online": true}', b'{"timestamp": 1}', b'{"online": "true", "timestamp": 1}', b'{"online": 1, "timestamp": 1}',
    b"[true, 1]", b'"ONLINE"', b"ONLINE", b"OFFLINE", b"null", b"42", b"", b"\xff\xfe\x00garbage", b"{" * 100_000,
    b"[" * 500 + b"]" * 500, json.dumps({"online": True, "timestamp": 1, "pad": "x" * 2000}).encode(),
    json.dumps({"online": True, "timestamp": NOW + TOLERANCE + 1}).encode(),
])
def test_a_state_that_is_not_the_specifications_or_stamped_ahead_is_refused_saying_why(raw):
    with pytest.raises(HostStateRefused) as err:
        read_state(raw, NOW, TOLERANCE)
    text = str(err.value)
    assert "expected JSON" in text or "ahead of this clock" in text
    assert len(text) < 400  # a log line, whatever the payload held


def test_a_state_of_the_specification_within_the_tolerance_is_read():
    assert read_state(b'{"online": true, "timestamp": 0}', NOW, TOLERANCE) == HostState(True, 0)
    assert read_state(json.dumps({"online": False, "timestamp": NOW + TOLERANCE}).encode(), NOW, TOLERANCE) == \
        HostState(False, NOW + TOLERANCE)
    assert read_state(b'{"online": true, "timestamp": 1.7e12, "extra": [1]}', NOW, TOLERANCE) == \
        HostState(True, 1_700_000_000_000)  # a whole number written as a float, and keys the node does not read


def test_the_refusal_of_a_future_stamp_says_how_far_ahead_and_what_to_check():
    with pytest.raises(HostStateRefused, match=r"3\.6e\+03 s ahead of this clock \(at most 300 s.*NTP"):
        read_state(json.dumps({"online": True, "timestamp": NOW + 3_600_000}).encode(), NOW, TOLERANCE)
    with pytest.raises(HostStateRefused, match=r"1e\+30 is centuries ahead"):
        read_state(b'{"online": true, "timestamp": 1e30}', NOW, TOLERANCE)


class FakeClock:
    def __init__(self) -> None:
        self.t = 1000.0

    def __call__(self) -> float:
        return self.t


def test_rebirth_requests_within_the_interval_get_one_birth_at_its_end():
    clock = FakeClock()
    limit = BirthLimit(2.0, clock)
    assert limit.due_in() is None and limit.request()  # no birth yet: at once
    limit.born()
    clock.t += 0.5
    assert [limit.request() for _ in range(3000)] == [False] * 3000  # within the interval: deferred, together
    assert limit.due_in() == pytest.approx(1.5)
    clock.t += 1.5
    assert limit.due_in() == 0.0
    limit.born()  # the one birth that answers them all
    assert limit.due_in() is None and (limit.requests, limit.deferred) == (3001, 3000)
    clock.t += 2.0
    assert limit.request()  # a request a whole interval after the last birth: at once


def test_a_birth_for_another_reason_answers_the_waiting_requests():
    clock = FakeClock()
    limit = BirthLimit(5.0, clock)
    limit.born()
    assert not limit.request()
    clock.t += 1.0
    limit.born()  # a reconnection's birth
    assert limit.due_in() is None
    assert not limit.request() and limit.due_in() == pytest.approx(5.0)
    limit.forget()  # no session to birth again: the next connection's birth answers it
    assert limit.due_in() is None


def test_many_requests_over_a_long_time_give_one_birth_per_interval():
    clock = FakeClock()
    limit, births = BirthLimit(2.0, clock), 0
    for _ in range(3000):  # a request every 10 ms for 30 s, served as the node's control loop serves them
        clock.t += 0.01
        if limit.request() or limit.due_in() == 0.0:
            limit.born()
            births += 1
    assert 14 <= births <= 16  # 30 s / 2 s
