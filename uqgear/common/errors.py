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
    """Base class of all user-input errors raised by uqgear.

    A :class:`ValueError`, so one ``except`` clause catches every mistake in
    the input (a design, an operating point, a study, a rig file), and the
    message names the key, file or variable and what was expected.

    Examples
    --------
    >>> import uqgear
    >>> issubclass(uqgear.UqgearError, ValueError)
    True
    >>> try:
    ...     uqgear.load_design("locomotive", {"z1": 2})
    ... except uqgear.UqgearError as error:
    ...     print(type(error).__name__, "-", error)
    DesignError - z1: expected a value in [6, 400] teeth; got 2
    """


class DesignError(UqgearError):
    """A gear design is missing a key, has an unknown key or an implausible value.

    Examples
    --------
    >>> import uqgear
    >>> issubclass(uqgear.DesignError, ValueError)
    True
    >>> try:
    ...     uqgear.load_design("no-such-design")
    ... except uqgear.DesignError as error:
    ...     print(error)
    design 'no-such-design': not a bundled design (locomotive, pair_17_38) nor an existing file
    """


class OperatingPointError(UqgearError):
    """An operating point (speed, torque, ...) is outside what the model accepts.

    Examples
    --------
    >>> import uqgear
    >>> issubclass(uqgear.OperatingPointError, ValueError)
    True
    >>> design = uqgear.load_design("locomotive")
    >>> try:
    ...     uqgear.build_model(design, pinion_speed=-100.0, drive_torque=7000.0, adhesion_torque=33e3)
    ... except uqgear.OperatingPointError as error:
    ...     print(error)
    pinion_speed: expected a finite value > 0 rpm; got -100.0
    """


class ParameterSpaceError(UqgearError):
    """An uncertain-parameter definition is malformed (inverted interval, unknown distribution, ...).

    Examples
    --------
    >>> import uqgear
    >>> issubclass(uqgear.ParameterSpaceError, ValueError)
    True
    >>> try:
    ...     uqgear.Interval(2.0, 1.0)
    ... except uqgear.ParameterSpaceError as error:
    ...     print(error)
    Interval(2.0, 1.0): inverted interval, expected lower < upper; got lower=2.0 > upper=1.0
    """


class StudyError(UqgearError):
    """A study definition does not follow the study schema.

    Examples
    --------
    >>> import uqgear
    >>> issubclass(uqgear.StudyError, ValueError)
    True
    >>> try:
    ...     uqgear.parse_study("analyses: []")
    ... except uqgear.StudyError as error:
    ...     print(error)
    analyses: expected a non-empty list of analyses; got []
    """


class RigDataError(UqgearError):
    """A rig data file does not follow the ``uqgear-rig/1`` format.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> import uqgear
    >>> issubclass(uqgear.RigDataError, ValueError)
    True
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     path = pathlib.Path(folder) / "campaign.nc"
    ...     _ = path.write_text("not netCDF")
    ...     try:
    ...         uqgear.read_rig(path)
    ...     except uqgear.RigDataError as error:
    ...         print("not a readable netCDF-4 file" in str(error))
    True
    """


class ExecutionError(UqgearError):
    """A run could not be executed as configured (unreachable scheduler, failed chunk, ...).

    Examples
    --------
    >>> import uqgear
    >>> from uqgear.uq import Runner
    >>> issubclass(uqgear.ExecutionError, ValueError)
    True
    >>> try:
    ...     Runner(chunk_size=0)
    ... except uqgear.ExecutionError as error:
    ...     print(error)
    chunk_size: expected a positive integer; got 0
    """


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

    Examples
    --------
    A failure inside a step of accepted work names the step and keeps the
    original exception; it is not a :class:`ValueError`, unlike a user mistake:

    >>> import uqgear
    >>> from uqgear.common.errors import internal_step
    >>> issubclass(uqgear.InternalError, ValueError)
    False
    >>> try:
    ...     with internal_step("sum the mesh forces"):
    ...         1 / 0
    ... except uqgear.InternalError as error:
    ...     print(error.step, "|", error.detail, "|", type(error.cause).__name__)
    sum the mesh forces | ZeroDivisionError: division by zero | ZeroDivisionError
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

    Examples
    --------
    A 17-tooth pinion without profile shift is slightly undercut: the design
    is accepted with a warning of this family, which a filter can silence:

    >>> import warnings
    >>> import uqgear
    >>> with warnings.catch_warnings(record=True) as caught:
    ...     warnings.simplefilter("always", uqgear.UqgearWarning)
    ...     design = uqgear.load_design("pair_17_38")
    >>> [issubclass(warning.category, uqgear.UqgearWarning) for warning in caught][:1]
    [True]
    >>> with warnings.catch_warnings():
    ...     warnings.simplefilter("error")
    ...     warnings.simplefilter("ignore", uqgear.UqgearWarning)
    ...     design = uqgear.load_design("pair_17_38")
    >>> design.z1
    17
    """


class DesignWarning(UqgearWarning):
    """A gear design is modelled, but its geometry carries a caveat.

    Examples
    --------
    >>> import warnings
    >>> import uqgear
    >>> issubclass(uqgear.DesignWarning, uqgear.UqgearWarning), issubclass(uqgear.DesignWarning, ValueError)
    (True, False)
    >>> with warnings.catch_warnings(record=True) as caught:
    ...     warnings.simplefilter("always", uqgear.DesignWarning)
    ...     design = uqgear.load_design("pair_17_38")
    >>> sorted({warning.category.__name__ for warning in caught})
    ['UndercutWarning']
    """


class UndercutWarning(DesignWarning):
    """A tooth is undercut by its generating rack: modelled from its form circle (docs/model/geometry.md section 3).

    Raised as a warning, not an error: a marginal undercut (a 17-tooth
    pinion without profile shift) is everyday practice. The message names the
    shift key, the least shift without undercut, the form radius and the
    contact ratio that follow.

    Examples
    --------
    A 16-tooth pinion needs a profile shift x1 of 0.064 to escape undercut:

    >>> import warnings
    >>> import uqgear
    >>> base = uqgear.load_design("locomotive")
    >>> with warnings.catch_warnings(record=True) as caught:
    ...     warnings.simplefilter("always", uqgear.UndercutWarning)
    ...     design = base.replace(z1=16, x1=0.0, x2=0.0)
    >>> print(str(caught[0].message)[:63])
    x1: the pinion (z1=16, x1=0) is undercut (none from x1 = 0.064)
    >>> with warnings.catch_warnings(record=True) as caught:
    ...     warnings.simplefilter("always", uqgear.UndercutWarning)
    ...     design = base.replace(z1=16, x1=0.1, x2=0.0)
    >>> len(caught)
    0
    """
