"""Checks of analysis settings: finite numbers, counts and quantile levels.

Every analysis of the uncertainty layer checks its settings with these, so a
wrong value is reported the same way (a :class:`ParameterSpaceError` naming
the setting and what was expected).
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from typing import Any

import numpy as np

from ..common.errors import ParameterSpaceError


def finite_number(value: Any, where: str, expected: str = "a finite number") -> float:
    """Check that ``value`` is a finite real number (not a bool) and return it as a float."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise ParameterSpaceError(f"{where}: expected {expected}; got {value!r}")
    value = float(value)
    if not math.isfinite(value):
        raise ParameterSpaceError(f"{where}: expected {expected}; got {value!r}")
    return value


def check_count(value: Any, setting: str, minimum: int = 1, maximum: int | None = None) -> int:
    """Check that a count setting is an integer in ``[minimum, maximum]``.

    Raises
    ------
    ParameterSpaceError
        Naming ``setting`` and the expected range.
    """
    upper_text = "" if maximum is None else f" and <= {maximum}"
    if (
        isinstance(value, (bool, np.bool_))
        or not isinstance(value, (int, np.integer))
        or value < minimum
        or (maximum is not None and value > maximum)
    ):
        raise ParameterSpaceError(f"{setting}: expected an integer >= {minimum}{upper_text}; got {value!r}")
    return int(value)


def check_quantiles(quantiles: Iterable[float], setting: str = "quantiles") -> np.ndarray:
    """Check quantile levels: a non-empty 1-D sequence of numbers in [0, 1]."""
    try:
        levels = np.asarray(list(quantiles), dtype=float)
    except (TypeError, ValueError):
        raise ParameterSpaceError(f"{setting}: expected a sequence of numbers in [0, 1]; got {quantiles!r}") from None
    if (
        levels.ndim != 1
        or levels.size == 0
        or not np.all(np.isfinite(levels))
        or np.any(levels < 0)
        or np.any(levels > 1)
    ):
        raise ParameterSpaceError(f"{setting}: expected a sequence of numbers in [0, 1]; got {quantiles!r}")
    return levels
