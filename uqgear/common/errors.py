"""Exception types: user mistakes, and internal failures after the input was accepted.

Every error a user can cause (a bad design file, a wrong study key, a rig file
that does not follow the format) is a subclass of :class:`UqgearError`, itself
a :class:`ValueError`, so callers can catch one type and the command line can
turn it into a one-line message with exit status 2. Such errors are raised
before the work starts. A failure inside the work, once the input was
accepted, is :class:`InternalError` (raised by :func:`internal_step`, naming
the step): the command line reports it as internal, keeps the finished
outputs and exits with status 1.
"""

from __future__ import annotations

import reprlib
from collections.abc import Iterator
from contextlib import contextmanager


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


class InternalError(RuntimeError):
    """A failure of uqgear's own computation after its input was accepted.

    Not a :class:`UqgearError`: the input was checked and found valid before
    the work started, so the fault is ours, not the user's. The command line
    reports it as internal, with the step that failed, keeps the outputs
    finished so far and exits with status 1 (a user mistake gives 2).

    Parameters
    ----------
    step : str
        The step of the work that failed, e.g. ``"fit eccentricity[pinion]"``.
    cause : BaseException
        The exception raised inside the step (also the ``__cause__``).

    Attributes
    ----------
    step : str
    cause : BaseException
    kept : str or None
        Where the outputs finished before the failure were kept (set by
        whoever kept them; None while nothing was kept).
    finished : list of dict
        The steps finished before, with what each found
        (:class:`~uqgear.common.steps.StepLog` fills it in).
    """

    def __init__(self, step: str, cause: BaseException) -> None:
        self.step = str(step)
        self.cause = cause
        self.kept: str | None = None
        self.finished: list[dict] = []
        super().__init__(f"step {self.step!r} failed: {type(cause).__name__}: {cause}")

    @property
    def detail(self) -> str:
        """The failure of the step in one line: exception type and message."""
        return " ".join(f"{type(self.cause).__name__}: {self.cause}".split())


@contextmanager
def internal_step(step: str) -> Iterator[None]:
    """Run one step of work whose input was already accepted: any failure inside is ours.

    Every exception raised inside the block, a :class:`UqgearError` included
    (an internal value that a validating constructor refused is no fault of
    the user's), is re-raised as :class:`InternalError` naming ``step``.
    Steps nest: an :class:`InternalError` from an inner step passes through
    unchanged, so the innermost step is the one named. Ctrl-C and operating
    system errors (a full disk, a folder without write permission) pass
    through as they are: they are neither the input's fault nor ours.

    Parameters
    ----------
    step : str
        What the block does, for the message (``"fit nominal model"``).
    """
    try:
        yield
    except (InternalError, OSError):
        raise
    except Exception as exc:
        raise InternalError(step, exc) from exc


class UqgearWarning(UserWarning):
    """Base class of uqgear's warnings: an input accepted and modelled, with a caveat the user should know.

    The command line prints each as one line ``uqgear: warning: ...`` on
    standard error; in Python they are ordinary :mod:`warnings` (filter them
    by this class or a subclass).
    """


class DesignWarning(UqgearWarning):
    """A gear design is modelled, but its geometry carries a caveat."""


class UndercutWarning(DesignWarning):
    """A tooth is undercut by its generating rack: modelled from its form circle (docs/model.md section 3).

    Raised as a warning, not an error: a marginal undercut (a 17-tooth
    pinion without profile shift) is everyday practice. The message names the
    shift key, the least shift without undercut, the form radius and the
    contact ratio that follow.
    """
