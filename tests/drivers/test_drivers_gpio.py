"""Button, indicator and the one place that picks the GPIO backend."""

import pytest
from gpiozero import Device
from gpiozero.pins.mock import MockFactory

from drivers import backend
from drivers.button import PushButton
from drivers.errors import DriverConfigError
from drivers.indicator import Indicator


def press(button):
    button.pin.drive_low()  # pull-up wiring: pressed pulls the line to ground
    button.pin.drive_high()


def test_each_press_calls_when_pressed_once(factory):
    calls = []
    with PushButton(27, bounce_time=None, pin_factory=factory) as b:
        b.when_pressed = lambda: calls.append(1)
        press(b)
        press(b)
        assert calls == [1, 1] and b.presses == 2
        b.when_pressed = None
        press(b)
        assert calls == [1, 1] and b.presses == 3


def test_button_is_pressed_follows_the_pin_and_close_detaches(factory):
    calls = []
    b = PushButton(27, pin_factory=factory)
    b.when_pressed = lambda: calls.append(1)
    pin = b.pin
    pin.drive_low()
    assert b.is_pressed
    pin.drive_high()
    b.close()
    b.close()
    assert (b.is_pressed, b.when_pressed, calls) == (False, None, [1])


def test_button_bounce_time_is_validated(factory):
    with pytest.raises(DriverConfigError, match="bounce_time"):
        PushButton(27, bounce_time=5, pin_factory=factory)


def test_led_patterns_follow_the_state(factory):
    with Indicator(22, pin_factory=factory) as led:
        led.show("IDLE")
        assert led.is_active and led.shown == "IDLE"
        led.show("CAPTURING")
        assert led.shown == "CAPTURING"
        led.show("FAULT")
        led.show("IDLE")
        assert led.is_active
        pin = led.pin
    assert pin.state is False  # closed: off


def test_buzzer_is_silent_while_busy(factory):
    with Indicator(22, kind="buzzer", pin_factory=factory) as bz:
        bz.show("ARMED")
        assert not bz.is_active
        bz.show("FAULT")
        bz.show("CAPTURING")
        assert not bz.is_active


def test_indicator_kind_is_validated(factory):
    with pytest.raises(DriverConfigError, match="kind"):
        Indicator(22, kind="siren", pin_factory=factory)


def test_mock_backend_is_shared_so_tests_reach_the_drivers_pins(monkeypatch):
    monkeypatch.setenv("GPIOZERO_PIN_FACTORY", "mock")
    f = backend.pin_factory()
    assert isinstance(f, MockFactory) and backend.is_mock()
    assert backend.pin_factory("mock") is f is Device.pin_factory


def test_explicit_backend_setting_wins_over_the_environment(monkeypatch):
    monkeypatch.setenv("GPIOZERO_PIN_FACTORY", "lgpio")
    assert backend.backend_name("mock") == "mock"
    assert isinstance(backend.pin_factory("mock"), MockFactory)


def test_unknown_backend_names_the_known_ones():
    with pytest.raises(DriverConfigError, match="unknown GPIO backend 'nonesuch'.*mock"):
        backend.pin_factory("nonesuch")
