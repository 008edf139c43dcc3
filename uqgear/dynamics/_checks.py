"""Input checks shared by the dynamics modules: tolerances, seeds, Dataset variables and attributes."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
import xarray as xr

from ..common.errors import UqgearError

Seed = int | np.random.SeedSequence


def check_positive(name: str, value: Any) -> float:
    """``value`` as a float, which must be finite and above 0; the :class:`UqgearError` names ``name``."""
    try:
        number = float(value)
    except (TypeError, ValueError):
        raise UqgearError(f"{name}: expected a positive number; got {value!r}") from None
    if not math.isfinite(number) or number <= 0.0:
        raise UqgearError(f"{name}: expected a positive finite number; got {value!r}")
    return number


def require_variables(ds: xr.Dataset, names: Sequence[str], what: str) -> None:
    """Refuse, naming ``what``, a ``ds`` that is not a Dataset or lacks one of the variables ``names``."""
    if not isinstance(ds, xr.Dataset):
        raise UqgearError(f"{what}: expected an xarray Dataset; got {type(ds).__name__}")
    missing = [name for name in names if name not in ds.variables]
    if missing:
        raise UqgearError(
            f"{what}: the Dataset lacks variable(s) {', '.join(missing)}; "
            f"it has {', '.join(sorted(map(str, ds.data_vars))) or 'none'}"
        )


def require_number_attr(ds: xr.Dataset, name: str, what: str) -> float:
    """The numeric attribute ``name`` of a :func:`~uqgear.physics.integration.simulate` result, as a float.

    Refuses, naming ``what``, a Dataset without the attribute or with one that is not a number.
    """
    if name not in ds.attrs:
        raise UqgearError(f"{what}: the Dataset lacks the attribute {name!r} (expected a simulate() result)")
    try:
        return float(ds.attrs[name])
    except (TypeError, ValueError):
        raise UqgearError(f"{what}: attribute {name!r} should be a number; got {ds.attrs[name]!r}") from None
