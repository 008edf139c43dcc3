"""Names and units of the variables a study may fix, sweep or make uncertain."""

from __future__ import annotations

from ..physics.design import DESIGN_KEYS, design_key_unit

#: Operating variables a study may fix or sweep, with units and plausible ranges.
#: Design keys (bearing stiffness, backlash, ...) may be swept or made uncertain too.
OPERATING_VARIABLES: dict[str, tuple[str, float, float]] = {
    "pinion_speed": ("rpm", 0.0, 1e5),
    # the model drives the pinion (T1 >= 0) against adhesion (T2 >= 0); it has no braking case
    "drive_torque": ("N m", 0.0, 1e7),
    "adhesion_torque": ("N m", 0.0, 1e7),
    "mesh_stiffness_scale": ("1 (factor on the Ishikawa mesh stiffness)", 1e-3, 100.0),
}
#: Design keys that may vary between the runs of one batch (the tooth counts may not).
VARIABLE_DESIGN_KEYS: tuple[str, ...] = tuple(key for key in DESIGN_KEYS if key not in ("z1", "z2"))
#: Every name an operating point, sweep or uncertain parameter may use.
VARIABLES: tuple[str, ...] = tuple(OPERATING_VARIABLES) + VARIABLE_DESIGN_KEYS


def variable_unit(name: str) -> str:
    """Unit text of an operating variable or design key."""
    if name in OPERATING_VARIABLES:
        return OPERATING_VARIABLES[name][0]
    if name in DESIGN_KEYS:
        return design_key_unit(name)
    return ""


def variable_units_short(name: str) -> str:
    """A short unit for axis labels (``rpm``, ``N m``, ``N/m``, ``1``)."""
    unit = variable_unit(name)
    short = unit.split(" (")[0].split(",")[0].strip()
    if name in (
        "zeta1",
        "zeta2",
        "zeta_mesh",
        "poisson_ratio",
        "x1",
        "x2",
        "addendum_coefficient",
        "dedendum_coefficient",
    ):
        return "1"
    return short or "1"
