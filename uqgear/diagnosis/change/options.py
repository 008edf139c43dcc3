"""The options of a diagnosis against a healthy reference: which route, and whether the gears were replaced."""

from __future__ import annotations

from typing import Any

from ..allowances.reference import ReferenceCorrection
from ..errors import DiagnosisError

#: The routes with a reference: what changed since it, or its transfer correction of the model.
ROUTES = ("change", "transfer")
#: The test campaign runs the reference's gears, or a replaced set of the same quality.
GEAR_STATES = ("same", "replaced")


def check_reference_options(route: Any, gears: Any) -> tuple[str, str]:
    """The route and the gears' state, checked (DiagnosisError naming the option otherwise)."""
    if route not in ROUTES:
        raise DiagnosisError(f"reference_route: expected one of {', '.join(ROUTES)}; got {route!r}")
    if gears not in GEAR_STATES:
        raise DiagnosisError(f"reference_gears: expected one of {', '.join(GEAR_STATES)}; got {gears!r}")
    return str(route), str(gears)


def is_differential(route: str, reference: Any) -> bool:
    """Whether a diagnosis takes the differential route: a reference campaign given and the ``change`` route
    (a transfer correction already learned goes the ``transfer`` route)."""
    return reference is not None and route == "change" and not isinstance(reference, ReferenceCorrection)


__all__ = ["GEAR_STATES", "ROUTES", "check_reference_options", "is_differential"]
