"""The error type of the calibration package."""

from __future__ import annotations

from ..common.errors import UqgearError


class CalibrationError(UqgearError):
    """A calibration setting or input is not valid."""
