"""The limits a study puts on operating points, run lengths and figures, for any caller.

The command line's ``simulate`` and ``report`` check their options here, so a
value a study would refuse is refused there too, with the same message.
"""

from __future__ import annotations

from typing import Any

from .checkers import number
from .settings import SIMULATION_SCHEMA, check_kept_within
from .variables import OPERATING_VARIABLES

#: Figure resolution of reports, dots per inch (the study key ``outputs.dpi``).
DPI = number("dots per inch", 50, 600, integer=True)


def check_operating_value(name: str, value: Any, where: str) -> float:
    """``value`` of the operating variable ``name`` within a study's limits.

    Parameters
    ----------
    name : {"pinion_speed", "drive_torque", "adhesion_torque", "mesh_stiffness_scale"}
    value : number
    where : str
        What to call it in a message (a study key path or a command-line option).

    Raises
    ------
    StudyError
        Not a finite number in the variable's range.
    """
    unit, lower, upper = OPERATING_VARIABLES[name]
    return number(unit, lower, upper, lower_open=name == "pinion_speed")(value, where)


def check_run_length(n_periods: Any, keep_periods: Any, *, where: tuple[str, str]) -> tuple[int, int]:
    """Mesh periods integrated and kept, within a study's limits, kept <= integrated.

    ``where`` names the two values in messages.
    """
    total = SIMULATION_SCHEMA["n_periods"](n_periods, where[0])
    kept = SIMULATION_SCHEMA["keep_periods"](keep_periods, where[1])
    check_kept_within(total, kept, where[0], where[1])
    return total, kept


def check_dpi(value: Any, where: str) -> int:
    """A report figure resolution within a study's limits."""
    return DPI(value, where)


__all__ = ["DPI", "check_operating_value", "check_run_length", "check_dpi"]
