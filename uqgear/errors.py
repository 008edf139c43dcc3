"""Exception types raised for user mistakes.

Every error a user can cause (a bad design file, a wrong study key, a rig file
that does not follow the format) is a subclass of :class:`UqgearError`, itself
a :class:`ValueError`, so callers can catch one type and the command line can
turn it into a one-line message with exit status 2.
"""

from __future__ import annotations


class UqgearError(ValueError):
    """Base class of all user-input errors raised by uqgear."""


class DesignError(UqgearError):
    """A gear design is missing a key, has an unknown key or an implausible value."""


class OperatingPointError(UqgearError):
    """An operating point (speed, torque, ...) is outside what the model accepts."""


class ParameterSpaceError(UqgearError):
    """An uncertain-parameter definition is malformed (inverted interval, unknown distribution, ...)."""


class StudyError(UqgearError):
    """A study definition does not follow the study schema."""


class RigDataError(UqgearError):
    """A rig data file does not follow the ``uqgear-rig/1`` format."""


class ExecutionError(UqgearError):
    """A run could not be executed as configured (unreachable scheduler, failed chunk, ...)."""
