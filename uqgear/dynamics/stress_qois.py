"""Tooth root and flank stresses as scalar QoIs of a batch of runs, for every analysis that takes QoIs.

The kernels of :func:`~uqgear.physics.integration.simulate_batch` reduce each
run to scalar QoIs as they integrate; a tooth's stress follows from the load
of its pair, and with ``stresses`` they also keep, in the same pass, the
extremes of the pair loads over the kept grid steps
(:mod:`uqgear.physics._pair_extremes`). The root stress is a constant of each
gear times the pair load and the flank stress a constant times
``sqrt(P+ / rho)`` on that gear's dedendum, so those extremes give the peak
and amplitude of the root and flank stress of each gear (:data:`STRESS_QOI_INFO`,
:func:`~uqgear.dynamics.tooth_loads.peaks_from_extremes`):
:func:`tooth_stress_qois` runs the batch once and converts.
:class:`StressEvaluator` is :class:`~uqgear.physics.integration.BatchEvaluator`
with those QoIs beside the kernels' own, from the same runs, so an interval,
Monte Carlo, polynomial chaos or Sobol analysis bounds a stress as it bounds
the mesh force at the cost of the runs alone. The stresses are read at the
kernels' grid steps (``steps_per_mode`` per period of the highest natural
frequency): within a few parts in a thousand of those of a history sampled
finely (:func:`~uqgear.dynamics.tooth_loads.tooth_stresses`; tests/test_stress_qois.py).

The stresses are ISO 6336's (docs/model/rating.md): the root stress at the
critical section of method B with the load where it acts, the flank stress by
Hertz with the standard's elasticity and contact-ratio factors, each with the
rating's load factors K_A, K_Hbeta and K_Halpha and no K_v (the simulated load
is the dynamic load). At a crawl, with a mesh stiffness without jumps, the root
stress peaks are the static ISO stresses.
"""

from __future__ import annotations

from collections.abc import Sequence
from functools import lru_cache
from typing import Any

import numpy as np
import xarray as xr

from ..physics.batch_setup import PAIR_EXTREME_INFO, sample_designs, start_states
from ..physics.design import Design
from ..physics.integration import QOI_INFO, BatchEvaluator, simulate_batch
from ..physics.pitch_errors import PitchErrors
from ..physics.rating import RatingSettings, StaticRating, static_rating
from .tooth_loads import GEARS, peaks_from_extremes

#: The stress QoIs: name -> (units, description); ``<quantity>_<gear>`` for each gear of :data:`GEARS`.
STRESS_QOI_INFO: dict[str, tuple[str, str]] = {
    f"{quantity}_{gear}": ("Pa", f"{text} of the {gear}'s teeth in the kept section")
    for quantity, text in (
        ("root_stress_peak", "largest tooth root stress (ISO 6336-3 method B critical section)"),
        ("root_stress_amplitude", "half the largest range of the tooth root stress"),
        ("contact_stress_peak", "largest flank contact stress (Hertz, ISO 6336-2 factors)"),
        ("contact_stress_amplitude", "half the largest range of the flank contact stress"),
    )
    for gear in GEARS
}
#: The stress QoIs' names.
STRESS_QOIS: tuple[str, ...] = tuple(STRESS_QOI_INFO)
#: Every scalar QoI of a run: the batch kernels' (:data:`~uqgear.physics.integration.QOI_INFO`) and the stresses'.
RUN_QOI_INFO: dict[str, tuple[str, str]] = {**QOI_INFO, **STRESS_QOI_INFO}


@lru_cache(maxsize=256)
def _rating(design: Design, drive_torque: float, pinion_speed: float, settings: RatingSettings) -> StaticRating:
    # K_v = 1: the simulated pair loads carry the dynamics
    return static_rating(design, drive_torque, pinion_speed, settings, dynamic_factor=1.0)


def _operating(samples: xr.Dataset, name: str, default: float) -> np.ndarray:
    if name in samples.data_vars:
        return np.asarray(samples[name].values, dtype=float)
    return np.full(samples.sizes["sample"], float(default))


def stress_variables(
    design: Design, samples: xr.Dataset, batch: xr.Dataset, rating: RatingSettings | None = None
) -> dict[str, xr.Variable]:
    """The stress QoIs (:data:`STRESS_QOI_INFO`) of a batch run with ``stresses``, from its pair-load extremes.

    Parameters
    ----------
    design : Design
    samples : xarray.Dataset
        The batch's samples (their ``pinion_speed`` and ``drive_torque`` rate each run).
    batch : xarray.Dataset
        :func:`~uqgear.physics.integration.simulate_batch`'s result with ``stresses=True``.
    rating : RatingSettings, optional
        ISO 6336 inputs (:func:`tooth_stress_qois`).

    Returns
    -------
    dict
        Name -> variable on ``sample``, Pa.
    """
    settings = rating if rating is not None else RatingSettings()
    torques = _operating(samples, "drive_torque", design.operation.drive_torque)
    speeds = np.asarray(samples["pinion_speed"].values, dtype=float)
    extremes = np.stack([np.asarray(batch[name].values, dtype=float) for name in PAIR_EXTREME_INFO], axis=1)
    names = [name.rsplit("_", 1) for name in STRESS_QOIS]
    values = np.empty((len(speeds), len(STRESS_QOIS)))
    for i, (run, torque, speed) in enumerate(zip(sample_designs(design, samples), torques, speeds)):
        peaks = peaks_from_extremes(run, _rating(run, float(torque), float(speed), settings), extremes[i])
        values[i] = [peaks[quantity][GEARS.index(gear)] for quantity, gear in names]
    return {
        name: xr.Variable("sample", values[:, j], {"units": units, "long_name": text})
        for j, (name, (units, text)) in enumerate(STRESS_QOI_INFO.items())
    }


def tooth_stress_qois(
    design: Design,
    samples: xr.Dataset,
    *,
    n_periods: int = 400,
    keep_periods: int = 200,
    steps_per_mode: int = 24,
    effects: Sequence[Any] = (),
    damping_in_separation: bool = True,
    stiffness: str = "ishikawa",
    pitch_errors: PitchErrors | None = None,
    rating: RatingSettings | None = None,
    initial_states: np.ndarray | None = None,
    threads: int | None = 1,
) -> xr.Dataset:
    """The tooth stress QoIs of every sample, from one batch pass that keeps each run's pair-load extremes.

    Parameters
    ----------
    design : Design
    samples : xarray.Dataset
        Dim ``sample``, the variables of :func:`~uqgear.physics.integration.simulate_batch`'s samples.
    n_periods, keep_periods, steps_per_mode, effects, damping_in_separation, stiffness, pitch_errors
        As in :func:`~uqgear.physics.integration.simulate_batch`.
    rating : RatingSettings, optional
        The ISO 6336 inputs the stresses take (load factors, the basic rack's root fillet); the
        defaults of :class:`~uqgear.physics.rating.RatingSettings` where not given.
    initial_states : ndarray, optional
        (samples, 6) start states; a row of NaN, or none given, starts that run at rest.
    threads : int, optional
        Threads of the batch (None: all cores); the numbers do not depend on it.

    Returns
    -------
    xarray.Dataset
        Dim ``sample``: the variables of :data:`STRESS_QOI_INFO`, Pa.

    Examples
    --------
    At a crawl, with a mesh stiffness without jumps (the Ishikawa table's jump where a pair leaves sets
    the mesh ringing, which the kernels' steps resolve), the pinion's root stress peak is ISO 6336-3's
    sigma_F at K_v = 1 (within the transmission error's own load variation):

    >>> import uqgear
    >>> from uqgear.physics.rating import static_rating
    >>> from uqgear.dynamics.stress_qois import tooth_stress_qois
    >>> design = uqgear.load_design("locomotive")
    >>> samples = uqgear.samples_from_mapping({"pinion_speed": [5.0], "drive_torque": [7000.0]})
    >>> qois = tooth_stress_qois(design, samples, n_periods=30, keep_periods=10, stiffness="constant")
    >>> iso = static_rating(design, 7000.0, 5.0, dynamic_factor=1.0)
    >>> abs(float(qois["root_stress_peak_pinion"][0]) / iso.root_stress[0] - 1.0) < 0.01
    True
    """
    batch = simulate_batch(
        design,
        samples,
        n_periods=n_periods,
        keep_periods=keep_periods,
        effects=effects,
        damping_in_separation=damping_in_separation,
        stiffness=stiffness,
        steps_per_mode=steps_per_mode,
        threads=threads,
        pitch_errors=pitch_errors,
        initial_states=start_states(
            design, samples, initial_states, effects=effects, damping_in_separation=damping_in_separation,
            stiffness=stiffness,
        ),
        stresses=True,
    )
    return xr.Dataset(
        stress_variables(design, samples, batch, rating),
        coords={"sample": samples["sample"].values} if "sample" in samples.coords else None,
    )


class StressEvaluator(BatchEvaluator):
    """:class:`~uqgear.physics.integration.BatchEvaluator` with the tooth stress QoIs beside its own.

    Parameters
    ----------
    design : Design
    rating : RatingSettings, optional
        ISO 6336 inputs of the stresses (:func:`tooth_stress_qois`).
    **options
        Those of :class:`~uqgear.physics.integration.BatchEvaluator`.

    Examples
    --------
    The pinion's root stress over the adhesion torque at 3000 rpm, MPa:

    >>> import uqgear
    >>> from uqgear.dynamics.stress_qois import StressEvaluator
    >>> model = StressEvaluator(uqgear.load_design("locomotive"), fixed={"pinion_speed": 3000.0},
    ...                         n_periods=60, keep_periods=20)
    >>> out = model(uqgear.samples_from_mapping({"adhesion_torque": [21e3, 33.8e3]}))
    >>> bool((out["root_stress_peak_pinion"].diff("sample") > 0).all()), "peak_mesh_force" in out
    (True, True)
    """

    def __init__(self, design: Design, *, rating: RatingSettings | None = None, **options: Any) -> None:
        # the kernels' QoIs and the pair-load extremes of one pass; the QoIs are those without them, bit for bit
        super().__init__(design, **{**options, "stresses": True})
        self.rating = rating

    def __call__(self, samples: xr.Dataset) -> xr.Dataset:
        completed = self.completed(samples)
        result = super().__call__(completed)
        stresses = stress_variables(self.design, completed, result, self.rating)
        return result.drop_vars(list(PAIR_EXTREME_INFO)).assign(stresses)

    def key(self) -> str:
        """:meth:`BatchEvaluator.key` with the stresses' rating inputs."""
        rating = self.rating if self.rating is not None else RatingSettings()
        return repr((super().key(), "tooth_stresses", repr(rating)))


__all__ = [
    "RUN_QOI_INFO",
    "stress_variables",
    "STRESS_QOI_INFO",
    "STRESS_QOIS",
    "StressEvaluator",
    "tooth_stress_qois",
]
