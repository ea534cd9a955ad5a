"""Errors of the measurement package.

Every error says what was wrong and what was expected. ``InvalidInput`` marks
errors caused by the user's data or settings (the CLI turns them into one
line on stderr and exit status 2); anything else escaping is a bug.
"""


class MeasurementError(Exception):
    """Base of all errors raised by ``measurement``."""


class InvalidInput(MeasurementError, ValueError):
    """The caller's data or settings are unusable; the message says why."""


class TraceError(InvalidInput):
    """An angle trace is malformed (columns, ordering, gaps, too short)."""


class RigError(InvalidInput):
    """A rig description is inconsistent or has non-physical constants."""


class UnknownEffectError(InvalidInput):
    """An effect name is not in the effect library."""


class CalibrationError(InvalidInput):
    """Calibration references are insufficient or inconsistent."""


class VisionError(InvalidInput):
    """A camera description or an image is unusable."""


class IdentificationError(MeasurementError):
    """The fit could not produce a result from otherwise valid data."""


class TensorError(InvalidInput):
    """A tensor plan or a multi-orientation set that cannot determine the inertia tensor."""


class ResultSchemaError(InvalidInput):
    """A stored or received result JSON is of another schema than the one this version reads."""
