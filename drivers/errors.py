"""Errors of the device drivers.

Configuration errors (a wrong pin, port, register or limit in the settings)
subclass ``measurement.errors.InvalidInput``: the CLI prints them as one line
and exits with status 2. Runtime faults of a device (an encoder that stops
answering) are ``DeviceFault``s: the sequencer turns them into its FAULT state
with the message as the reason.
"""

from __future__ import annotations

from measurement.errors import InvalidInput


class DriverError(Exception):
    """Base of all errors raised by ``drivers``."""


class DriverConfigError(DriverError, InvalidInput):
    """A driver setting is unusable (pin, port, register, limit); the message says what was expected."""


class VideoFileError(DriverError, InvalidInput):
    """A video file or image folder is missing, unreadable or malformed; the message says which and why."""


class DeviceFault(DriverError):
    """A device misbehaved at run time; the message says which device and why."""


class SensorFault(DeviceFault):
    """An angle sensor (encoder or camera) cannot deliver samples."""


class EncoderFault(SensorFault):
    """The Modbus RTU encoder failed: a run of time-outs, CRC errors or exception replies, or a lost port.

    ``counts`` holds the error counters at the time of the fault (same keys as
    ``ModbusEncoder.stats()``).
    """

    def __init__(self, message: str, counts: dict | None = None):
        super().__init__(message)
        self.counts = dict(counts or {})
