"""Whether a reference campaign can serve a test campaign: the same design and channels, every test run matched.

Both campaigns must state the same design (every key of the ``design``
attribute) and the reference must hold every channel of the test campaign;
every test operating point needs a reference point at the same pinion speed
and drive torque (``speed_tolerance`` and ``torque_tolerance`` of
:class:`~uqgear.diagnosis.DiagnosisSettings`). Checked before any work.
"""

from __future__ import annotations

import json
import math
from typing import Any

import numpy as np
import xarray as xr

from ..errors import DiagnosisError
from ..settings import DEFAULT_SETTINGS


def _design_dict(rig: xr.Dataset, where: str) -> dict[str, Any]:
    try:
        design = json.loads(str(rig.attrs.get("design", "")))
    except ValueError:
        raise DiagnosisError(f"{where}: design: expected a JSON object") from None
    if not isinstance(design, dict):
        raise DiagnosisError(f"{where}: design: expected a JSON object")
    return design


def _same(a: Any, b: Any) -> bool:
    if isinstance(a, (int, float)) and isinstance(b, (int, float)) and not isinstance(a, bool):
        return math.isclose(float(a), float(b), rel_tol=1e-9, abs_tol=1e-15)
    return a == b


def check_design_match(test: xr.Dataset, reference: xr.Dataset, *, where: str) -> None:
    """Refuse a reference campaign whose stated design or channels differ from the test campaign's.

    Raises
    ------
    DiagnosisError
        Naming ``where`` (the reference file) and the first keys that differ.
    """
    ours, theirs = _design_dict(test, "rig data"), _design_dict(reference, where)
    differ = [
        key
        for key in sorted(set(ours) | set(theirs))
        if key not in ours or key not in theirs or not _same(ours[key], theirs[key])
    ]
    if differ:
        shown = ", ".join(f"{key} {theirs.get(key, 'missing')} (test {ours.get(key, 'missing')})" for key in differ[:4])
        more = f" and {len(differ) - 4} more" if len(differ) > 4 else ""
        raise DiagnosisError(
            f"reference {where}: design differs from the test campaign's: {shown}{more}; "
            "expected a campaign of the same gear pair on the same rig"
        )
    from ...rig.sampling import SIGNAL_CHANNELS

    missing = [name for name in SIGNAL_CHANNELS if name in test.data_vars and name not in reference.data_vars]
    if missing:
        raise DiagnosisError(
            f"reference {where}: no channel {', '.join(missing)}; expected every channel of the test campaign"
        )


def match_operating_points(
    test: xr.Dataset,
    reference: xr.Dataset,
    *,
    where: str,
    speed_tolerance: float = DEFAULT_SETTINGS.reference.speed_tolerance,
    torque_tolerance: float = DEFAULT_SETTINGS.reference.torque_tolerance,
) -> np.ndarray:
    """For each test operating point the reference one at the same speed and drive torque.

    Returns
    -------
    ndarray of int (n_op,)
        Index of the matched reference run (the closest in relative speed and torque).

    Raises
    ------
    DiagnosisError
        A test run without a reference run within the tolerances (the first one is named).
    """
    speeds = np.asarray(test["pinion_speed"].values, dtype=float)
    torques = np.asarray(test["drive_torque"].values, dtype=float)
    ref_speeds = np.asarray(reference["pinion_speed"].values, dtype=float)
    ref_torques = np.asarray(reference["drive_torque"].values, dtype=float)
    matched = np.zeros(speeds.size, dtype=int)
    for op, (speed, torque) in enumerate(zip(speeds, torques)):
        speed_off = np.abs(ref_speeds - speed) / speed
        # a torque near zero is matched against a small absolute scale (1 N m)
        torque_off = np.abs(ref_torques - torque) / max(abs(torque), 1.0)
        fits = (speed_off <= speed_tolerance) & (torque_off <= torque_tolerance)
        if not fits.any():
            raise DiagnosisError(
                f"reference {where}: test operating point {op} ({speed:g} rpm, {torque:g} N m) has no reference "
                f"operating point within {speed_tolerance:.0%} in pinion speed and {torque_tolerance:.0%} in "
                "drive torque; expected a reference campaign covering the test plan"
            )
        distance = np.where(fits, speed_off / speed_tolerance + torque_off / torque_tolerance, np.inf)
        matched[op] = int(np.argmin(distance))
    return matched


# ---------------------------------------------------------------------------------------------- the correction


__all__ = ["check_design_match", "match_operating_points"]
