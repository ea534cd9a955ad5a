"""Errors of the measurement sequencer.

``SequencerConfigError`` (a setting out of range) is an ``InvalidInput``: the
CLI prints one line and exits 2. Run-time problems during a measurement are
not raised to the caller: they put the sequencer in FAULT with the reason
(see ``firmware_host.Sequencer``). ``IllegalTransition`` is a bug in the
sequencer itself.
"""

from __future__ import annotations

from measurement.errors import InvalidInput


def fault_words(exc: BaseException) -> str:
    """The one place a fault's words are made from an exception: what went wrong, as the pages, the history and
    the replies show it, without the exception's class name (a programmer's word; the log keeps it)."""
    return str(exc).strip() or "an error without a message (the appliance log names it)"


class SequencerError(Exception):
    """Base of all errors raised by ``firmware_host``."""


class SequencerConfigError(SequencerError, InvalidInput):
    """A sequencer setting is out of range; the message says what was expected."""


class IllegalTransition(SequencerError, RuntimeError):
    """The state machine was asked for a transition its table forbids (a bug)."""


class SequencerFault(SequencerError):
    """A step of a measurement failed; the message becomes the FAULT reason (raised inside ``poll`` only)."""


class CaptureTimeout(SequencerFault):
    """The sensor delivered no sample for longer than the capture time-out."""


class CaptureTooShort(SequencerFault):
    """The capture holds too few samples to identify anything."""


class IdentificationTimeout(SequencerFault):
    """Identification took longer than its time-out."""


class IdentificationFailed(SequencerFault):
    """Identification raised; the message names the error."""


class PublishFailed(SequencerFault):
    """The result sink raised."""
