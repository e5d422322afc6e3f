"""The one exception the core raises for bad input or a calibration it cannot trust."""


class CalibrationError(ValueError):
    """Input that cannot be calibrated, or a calibration that failed; the message says why."""
