"""The push button on its gpiozero mock pin drives the sequencer: one press, one measurement."""

from sequencer_harness import assert_solenoid_safe

from drivers.button import PushButton
from firmware_host import State


def press(button):
    button.pin.drive_low()
    button.pin.drive_high()


def test_one_press_starts_exactly_one_measurement_and_presses_during_it_are_ignored(harness, factory, caplog):
    button = PushButton(27, bounce_time=None, pin_factory=factory)
    h = harness(button=button)
    press(button)
    assert h.seq.busy
    with caplog.at_level("INFO", logger="moi.sequencer"):
        press(button)  # requested, not yet started
        h.step()
        assert h.seq.state is State.ARMED
        h.run_to(State.CAPTURING)
        press(button)
        press(button)
        h.run_to(State.IDLE)
    assert button.presses == 4
    assert h.path().count("ARMED") == 1 and len(h.results) == 1
    assert h.results[0].requested_by == "button"
    assert h.seq.counts["ignored_requests"] == 3
    ignored = [r for r in caplog.records if "ignored" in r.getMessage()]
    assert len(ignored) == 3
    assert "a measurement is running (CAPTURING)" in ignored[-1].getMessage()
    assert h.solenoid.pulses == 1
    assert_solenoid_safe(h)

    # back in IDLE, the next press is honoured (the operator latched the pendulum again)
    h.rig.relatch()
    press(button)
    h.step()
    h.run_to(State.IDLE)
    assert len(h.results) == 2 and h.solenoid.pulses == 2
    assert_solenoid_safe(h)
    button.close()


def test_closing_the_sequencer_detaches_the_button(harness, factory):
    button = PushButton(27, bounce_time=None, pin_factory=factory)
    h = harness(button=button)
    h.seq.close()
    press(button)
    assert button.presses == 1 and h.seq.state is State.IDLE and h.events == []
    assert button.when_pressed is None
    button.close()
