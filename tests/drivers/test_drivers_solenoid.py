"""The release solenoid: off by default, clamped pulses, off on every exit path (checked on the mock pin)."""

import math

import pytest

from drivers.errors import DeviceFault, DriverConfigError
from drivers.solenoid import ABSOLUTE_MAX_ON_TIME, Solenoid
from measurement.errors import InvalidInput

MAX_ON = 0.05  # s
# scheduling slack for the cut-off timer thread on a loaded CI machine, s: far below any request tested
SLACK = 0.25


def on_durations(pin):
    """Durations (s) of every on-interval recorded on a mock pin (active-high wiring)."""
    states = pin.states
    return [nxt.timestamp for cur, nxt in zip(states, states[1:]) if cur.state and not nxt.state]


def test_off_on_construction(factory):
    with Solenoid(17, max_on_time=MAX_ON, pin_factory=factory) as s:
        assert not s.is_active
        assert s.pin.state is False
        assert all(not st.state for st in s.pin.states)


def test_active_low_wiring_is_off_at_high_level(factory):
    with Solenoid(17, active_high=False, max_on_time=MAX_ON, pin_factory=factory) as s:
        assert (s.pin.state, s.is_active) == (True, False)
        s.pulse(10.0)
        assert (s.pin.state, s.is_active) == (False, True)
        assert s.wait_off(MAX_ON + SLACK + 1)
        assert s.pin.state is True


@pytest.mark.parametrize("asked", [10.0, 1e9, math.inf, 2 * MAX_ON])
def test_pulse_never_exceeds_the_maximum_whatever_is_asked(factory, asked):
    with Solenoid(17, max_on_time=MAX_ON, pin_factory=factory) as s:
        granted = s.pulse(asked)
        assert granted == MAX_ON
        assert s.is_active
        assert s.wait_off(MAX_ON + SLACK + 1), "the cut-off timer did not switch the coil off"
        assert (s.is_active, s.pin.state) == (False, False)
        (on,) = on_durations(s.pin)
        assert 0.9 * MAX_ON <= on < MAX_ON + SLACK


def test_short_pulse_is_granted_as_asked(factory):
    with Solenoid(17, max_on_time=MAX_ON, pin_factory=factory) as s:
        assert s.pulse(0.01) == 0.01
        assert s.wait_off(1 + SLACK)
        (on,) = on_durations(s.pin)
        assert 0.009 <= on < 0.01 + SLACK


@pytest.mark.parametrize("bad", [0.0, -1.0, math.nan, "1"])
def test_nonsense_duration_is_refused_and_the_coil_stays_off(factory, bad):
    with Solenoid(17, max_on_time=MAX_ON, pin_factory=factory) as s:
        with pytest.raises(ValueError, match="solenoid pulse duration must be > 0 s"):
            s.pulse(bad)
        assert not s.is_active
        assert on_durations(s.pin) == [] and s.pin.state is False


def test_no_second_pulse_while_energised(factory):
    with Solenoid(17, max_on_time=1.0, pin_factory=factory) as s:
        s.pulse(1.0)
        with pytest.raises(DeviceFault, match="already energised"):
            s.pulse(1.0)
        s.off()
        assert [st.state for st in s.pin.states] == [False, True, False]


def test_off_cuts_a_pulse_early_and_a_stale_timer_does_not_cut_the_next(factory):
    with Solenoid(17, max_on_time=0.3, pin_factory=factory) as s:
        s.pulse(0.3)
        s.off()
        assert (s.is_active, s.pin.state) == (False, False)
        s.pulse(0.3)  # the first pulse's timer was cancelled: this one runs its own course
        assert s.is_active
        assert s.wait_off(0.3 + SLACK + 1)
        assert [st.state for st in s.pin.states] == [False, True, False, True, False]


def test_off_on_close_twice_and_no_pulse_after_close(factory):
    s = Solenoid(17, max_on_time=1.0, pin_factory=factory)
    pin = s.pin
    s.pulse(1.0)
    s.close()
    s.close()
    assert pin.state is False and not s.is_active
    with pytest.raises(DeviceFault, match="after close"):
        s.pulse(0.1)
    assert pin.states[-1].state is False


def test_off_when_an_exception_leaves_the_with_block(factory):
    pins = []

    def release_and_crash():
        with Solenoid(17, max_on_time=1.0, pin_factory=factory) as s:
            pins.append(s.pin)
            s.pulse(1.0)
            raise RuntimeError("caller crashed mid-release")
    with pytest.raises(RuntimeError, match="caller crashed mid-release"):
        release_and_crash()
    (pin,) = pins
    assert pin.state is False
    assert pin.states[-1].state is False


def test_off_when_switching_on_fails(factory, monkeypatch):
    with Solenoid(17, max_on_time=1.0, pin_factory=factory) as s:
        import threading

        def broken_timer(*a, **k):
            raise RuntimeError("cannot start a thread")
        monkeypatch.setattr(threading, "Timer", broken_timer)
        with pytest.raises(RuntimeError):
            s.pulse(0.5)
        assert not s.is_active and s.pin.state is False


def test_listeners_see_on_and_off_and_cannot_keep_the_coil_on(factory):
    seen: list[bool] = []
    with Solenoid(17, max_on_time=MAX_ON, pin_factory=factory) as s:
        s.add_listener(seen.append)

        def crash(active):
            raise RuntimeError("observer bug")
        s.add_listener(crash)
        s.pulse(1.0)
        assert s.wait_off(MAX_ON + SLACK + 1)
    assert seen == [True, False]


@pytest.mark.parametrize("bad", [0, -0.1, ABSOLUTE_MAX_ON_TIME + 0.1, "0.2", True])
def test_max_on_time_is_validated(factory, bad):
    with pytest.raises(DriverConfigError, match="max_on_time") as err:
        Solenoid(17, max_on_time=bad, pin_factory=factory)
    assert isinstance(err.value, InvalidInput)


def test_bad_pin_is_a_config_error(factory):
    with pytest.raises(DriverConfigError, match="pin"):
        Solenoid(-3, pin_factory=factory)
