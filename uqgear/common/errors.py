"""Exception types raised for user mistakes.

Every error a user can cause (a bad design file, a wrong study key, a rig file
that does not follow the format) is a subclass of :class:`UqgearError`, itself
a :class:`ValueError`, so callers can catch one type and the command line can
turn it into a one-line message with exit status 2.
"""

from __future__ import annotations

import reprlib


def shown(value: object, limit: int = 80) -> str:
    """A bounded ``repr`` of a user's value for an error message.

    Never builds more than a prefix of the value: a huge string, a deeply
    nested or alias-expanded document is shown in at most ``limit``
    characters without formatting it whole first.
    """
    formatter = reprlib.Repr()
    formatter.maxlevel, formatter.maxdict, formatter.maxlist, formatter.maxtuple = 2, 4, 6, 6
    formatter.maxset = formatter.maxfrozenset = formatter.maxdeque = formatter.maxarray = 6
    formatter.maxstring = formatter.maxother = max(limit - 3, 10)
    text = formatter.repr(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."


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
