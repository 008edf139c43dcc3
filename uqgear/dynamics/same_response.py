"""When two runs of one operating point reached the same steady response.

Two runs reached the same attractor when their QoIs agree (:data:`COMPARED_QOIS` within ``tolerance``
relative, the time fractions :data:`COMPARED_FRACTIONS` within ``tolerance`` absolute) and their Poincare sets
are close (Hausdorff distance at most ``poincare_tolerance``); both tolerances are
:data:`NON_PERIODIC_FACTOR` times wider when either response is not periodic
(:mod:`uqgear.dynamics.attractors`). A run that repeats another bit for bit needs no comparison:
:func:`copies_of_first` finds them in one pass over a batch.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from .hausdorff import hausdorff

#: QoIs compared between runs (relative tolerance) and time fractions (absolute tolerance).
COMPARED_QOIS = ("peak_mesh_force", "dte_rms", "dte_peak_to_peak")
COMPARED_FRACTIONS = ("fraction_separation", "fraction_back_contact")
#: Factor on both tolerances when either response is not periodic.
NON_PERIODIC_FACTOR = 5.0


def same_response(a: dict[str, Any], b: dict[str, Any], settings: Any) -> bool:
    """Whether two runs' entries (compared QoIs and fractions, ``regime``, ``points``: the Poincare set in units of b
    and omega_h b) reached the same attractor under the tolerances of ``settings`` (a
    :class:`~uqgear.dynamics.attractors.MultiStart`; module docstring).

    Examples
    --------
    >>> from types import SimpleNamespace
    >>> settings = SimpleNamespace(tolerance=0.02, poincare_tolerance=0.05)
    >>> run = dict.fromkeys((*COMPARED_QOIS, *COMPARED_FRACTIONS), 1.0) | {"regime": "period-1"}
    >>> near = {**run, "dte_rms": 1.01, "points": np.array([[0.0, 0.04]])}
    >>> same_response({**run, "points": np.zeros((1, 2))}, near, settings)
    True
    >>> same_response({**run, "points": np.zeros((1, 2))}, {**near, "dte_rms": 1.05}, settings)
    False
    """
    periodic = str(a["regime"]).startswith("period-") and str(b["regime"]).startswith("period-")
    # a non-periodic response's extremes and point cloud are samples of the kept window: looser
    widen = 1.0 if periodic else NON_PERIODIC_FACTOR
    for name in COMPARED_QOIS:
        scale = max(abs(a[name]), abs(b[name]), 1e-300)
        if not abs(a[name] - b[name]) <= widen * settings.tolerance * scale:
            return False
    for name in COMPARED_FRACTIONS:
        if not abs(a[name] - b[name]) <= widen * settings.tolerance:
            return False
    return bool(hausdorff(a["points"], b["points"]) <= widen * settings.poincare_tolerance)


def copies_of_first(
    compared: Mapping[str, np.ndarray], regimes: np.ndarray, poincare_x: np.ndarray, poincare_v: np.ndarray
) -> np.ndarray:
    """Which runs (sample, start) are the sample's first run again, bit for bit: its QoIs, regime and Poincare points
    (NaN where it has NaN).

    Examples
    --------
    >>> points = np.array([[[0.1, np.nan], [0.1, np.nan], [0.2, np.nan]]])   # (sample, start, period)
    >>> copies_of_first({"dte_rms": np.array([[1.0, 1.0, 1.0]])}, np.array([["period-1"] * 3]), points, points)
    array([[ True,  True, False]])
    """
    same = regimes == regimes[:, :1]
    for values in compared.values():
        same &= values == values[:, :1]
    for points in (poincare_x, poincare_v):
        first = points[:, :1]
        same &= np.all((points == first) | (np.isnan(points) & np.isnan(first)), axis=2)
    return same


def self_same(entry: dict[str, Any]) -> bool:
    """Whether :func:`same_response` holds for the entry and itself, without the distances: every compared value
    finite and a Poincare point (a set's distance to itself is 0, within every tolerance).

    Examples
    --------
    >>> entry = dict.fromkeys((*COMPARED_QOIS, *COMPARED_FRACTIONS), 1.0)
    >>> self_same({**entry, "points": np.zeros((3, 2))}), self_same({**entry, "points": np.zeros((0, 2))})
    (True, False)
    """
    return all(math.isfinite(entry[name]) for name in (*COMPARED_QOIS, *COMPARED_FRACTIONS)) and bool(
        entry["points"].size
    )


__all__ = [
    "same_response",
    "copies_of_first",
    "self_same",
    "COMPARED_QOIS",
    "COMPARED_FRACTIONS",
    "NON_PERIODIC_FACTOR",
]
