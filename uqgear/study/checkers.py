"""Checkers of study values: each takes a value and its key path and returns the value or raises.

Every problem raises :class:`~uqgear.common.errors.StudyError` whose message
starts with the key path and says what was expected.
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable, Mapping, Sequence
from typing import Any

from ..common.errors import StudyError, shown

_NAME_PATTERN = re.compile(r"^[A-Za-z][A-Za-z0-9_-]{0,63}$")


Checker = Callable[[Any, str], Any]


def expectation_error(path: str, expected: str, value: Any) -> StudyError:
    """The :class:`StudyError` for a study entry at ``path``: what was expected and, shortened, what came.

    Every check of a study file words its refusals through it: ``"<path>: expected <expected>; got <value>"``.
    """
    return StudyError(f"{path}: expected {expected}; got {shown(value)}")


def value_kind(value: Any) -> str:
    """How a refusal names ``value``: 'a mapping', 'a list', or the value itself, shortened."""
    return "a mapping" if isinstance(value, Mapping) else ("a list" if isinstance(value, list) else shown(value))


def number(
    unit: str = "",
    lower: float | None = None,
    upper: float | None = None,
    *,
    integer: bool = False,
    lower_open: bool = False,
) -> Checker:
    """Checker of a finite number (optionally an integer) in a range."""
    kind = "an integer" if integer else "a number"
    if lower is not None and upper is not None:
        left = "(" if lower_open else "["
        expected = f"{kind} in {left}{lower:g}, {upper:g}]"
    elif lower is not None:
        expected = f"{kind} {'>' if lower_open else '>='} {lower:g}"
    else:
        expected = kind
    if unit:
        expected += f" {unit}"

    def check(value: Any, path: str) -> float | int:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise expectation_error(path, expected, value)
        if not math.isfinite(value):
            raise expectation_error(path, expected, value)
        if integer:
            if float(value) != int(value):
                raise expectation_error(path, expected, value)
            value = int(value)
        else:
            value = float(value)
        if lower is not None and (value < lower or (lower_open and value == lower)):
            raise expectation_error(path, expected, value)
        if upper is not None and value > upper:
            raise expectation_error(path, expected, value)
        return value

    check.expected = expected  # type: ignore[attr-defined]
    return check


def _checker(accepts: Callable[[Any], bool], expected: str) -> Checker:
    """Checker of a value that ``accepts`` takes, returned unchanged."""

    def check(value: Any, path: str) -> Any:
        if not accepts(value):
            raise expectation_error(path, expected, value)
        return value

    return check


def choice(*options: str) -> Checker:
    """Checker of one string among ``options``."""
    return _checker(lambda value: isinstance(value, str) and value in options, f"one of {', '.join(options)}")


def boolean() -> Checker:
    """Checker of true/false."""
    return _checker(lambda value: isinstance(value, bool), "true or false")


def string() -> Checker:
    """Checker of a string."""
    return _checker(lambda value: isinstance(value, str), "a string")


def identifier() -> Checker:
    """Checker of a name usable as a file name (letters, digits, _ and -)."""
    return _checker(
        lambda value: isinstance(value, str) and bool(_NAME_PATTERN.match(value)),
        "a name of letters, digits, '_' and '-' starting with a letter",
    )


def list_of(item: Checker, *, min_length: int = 1, unique: bool = False, what: str = "a list") -> Checker:
    """Checker of a list whose items pass ``item``; a single item is accepted as a list of one."""

    def check(value: Any, path: str) -> tuple:
        items = value if isinstance(value, list) else [value]
        if isinstance(value, (Mapping, tuple)) or value is None:
            raise expectation_error(path, what, value)
        checked = tuple(item(entry, f"{path}[{index}]") for index, entry in enumerate(items))
        if len(checked) < min_length:
            raise expectation_error(path, f"{what} of at least {min_length} item(s)", value)
        if unique and len(set(checked)) != len(checked):
            repeated = next(entry for entry in checked if checked.count(entry) > 1)
            raise StudyError(f"{path}: expected distinct entries; {repeated!r} is repeated")
        return checked

    return check


def check_mapping(
    value: Any, path: str, schema: Mapping[str, Checker], *, required: Sequence[str] = ()
) -> dict[str, Any]:
    """Validate a mapping against ``schema``: unknown keys, missing keys, each value."""
    where = path or "study"
    if not isinstance(value, Mapping):
        raise StudyError(f"{where}: expected a mapping with keys {', '.join(schema)}; got {value_kind(value)}")
    prefix = f"{path}." if path else ""
    for key in value:
        if not isinstance(key, str) or key not in schema:
            raise StudyError(f"{prefix}{key}: unknown key; expected one of {', '.join(schema)}")
    for key in required:
        if key not in value:
            raise StudyError(f"{prefix}{key}: missing (required)")
    return {key: schema[key](entry, f"{prefix}{key}") for key, entry in value.items()}


def class_range(lowest: float, highest: float) -> Checker:
    """Checker of ``[low, high]`` with ``lowest <= low <= high <= highest`` (a range of grades), or none."""
    expected = f"[lowest, highest] with {lowest:g} <= lowest <= highest <= {highest:g}, or none"

    def check(value: Any, path: str) -> tuple[float, float] | None:
        if value is None or value == "none":
            return None
        if (
            not isinstance(value, list)
            or len(value) != 2
            or not all(isinstance(entry, (int, float)) and not isinstance(entry, bool) for entry in value)
        ):
            raise expectation_error(path, expected, value)
        low, high = float(value[0]), float(value[1])
        if not lowest <= low <= high <= highest:
            raise expectation_error(path, expected, value)
        return low, high

    return check
