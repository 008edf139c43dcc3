"""The rig data a calibration fits: read or validated, with a usable signal, and order-tracked."""

from __future__ import annotations

import os
import time
from dataclasses import dataclass

import xarray as xr

from ..common.errors import RigDataError
from ..physics.design import Design
from ..rig.format import read_rig, rig_design, validate_rig
from ..rig.order_tracking import speed_summary, track_orders
from ..rig.ramp_records import steady_campaign
from ..rig.usability import check_usable_signal


@dataclass(frozen=True)
class AcceptedRig:
    """Rig data accepted for a calibration (:func:`accept_rig`)."""

    #: The campaign, order-tracked: every record at a constant speed; ramp records cut into operating points.
    rig: xr.Dataset
    #: Where the data came from: the file path, or the Dataset's title.
    source: str
    #: The nominal design: the one given, else the rig file's.
    design: Design
    #: Per-operating-point speed estimate of the order tracking (:func:`~uqgear.rig.order_tracking.speed_summary`).
    speed: list[dict[str, object]]
    #: Wall time of the order tracking, s.
    tracking_s: float


def accept_rig(rig: xr.Dataset | str | os.PathLike[str], design: Design | None) -> AcceptedRig:
    """Read or validate rig data for a calibration, check its signal, and track its orders.

    Parameters
    ----------
    rig : xarray.Dataset or path
        ``uqgear-rig/1`` data (a Dataset is validated, a path read).
    design : Design or None
        Nominal design replacing the file's (whose copy is then not
        validated as a design); None: the file's.

    Returns
    -------
    AcceptedRig

    Raises
    ------
    RigDataError
        The rig data do not follow the format, or carry no usable signal
        (:func:`~uqgear.rig.usability.check_usable_signal`).
    """
    if isinstance(rig, (str, os.PathLike)):
        source = where = str(rig)
        # a given design replaces the file's, whose copy is then not validated as a design
        rig = read_rig(rig, design=design)
    elif isinstance(rig, xr.Dataset):
        source = str(rig.attrs.get("title", "rig data"))
        where = "rig data"
        validate_rig(rig, where=where, design=design)
    else:
        raise RigDataError(f"rig: expected a uqgear-rig/1 Dataset or file path; got {type(rig).__name__}")
    # run-up and coast-down records become operating points (speed bins) beside the steady runs
    rig = steady_campaign(rig, design=design, where=where)
    # one run is enough: the priors regularise what a single run cannot separate
    check_usable_signal(rig, where=where, min_operating_points=1, purpose="the calibration")
    design = design if design is not None else rig_design(rig)
    # order tracking once, before any feature is read: every later step sees constant-speed records
    tracking_start = time.perf_counter()
    rig = track_orders(rig, design)
    speed = speed_summary(rig)
    return AcceptedRig(
        rig=rig, source=source, design=design, speed=speed, tracking_s=time.perf_counter() - tracking_start
    )
