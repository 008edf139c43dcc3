"""Tooth root and flank stresses as scalar QoIs of a batch of runs, for every analysis that takes QoIs.

The kernels of :func:`~uqgear.physics.integration.simulate_batch` reduce each
run to scalar QoIs as they integrate; a tooth's stress needs the load of each
tooth pair over the mesh cycle, which :func:`~uqgear.dynamics.tooth_loads.tooth_stresses`
derives from the run's DTE history (:func:`~uqgear.dynamics.tooth_loads.stress_peaks`, its scalar
part). :func:`tooth_stress_qois` runs the batch's
histories together (:func:`~uqgear.physics.history_batch.integrate_histories`,
the same numbers as a run alone) and reduces each to the peak and amplitude of
the root and flank stress of each gear (:data:`STRESS_QOI_INFO`);
:class:`StressEvaluator` is :class:`~uqgear.physics.integration.BatchEvaluator`
with those QoIs beside the kernels' own, so an interval, Monte Carlo,
polynomial chaos or Sobol analysis bounds a stress as it bounds the mesh force.

The stresses are ISO 6336's (docs/model/rating.md): the root stress at the
critical section of method B with the load where it acts, the flank stress by
Hertz with the standard's elasticity and contact-ratio factors, each with the
rating's load factors K_A, K_Hbeta and K_Halpha and no K_v (the simulated load
is the dynamic load). At a crawl the peaks are the static ISO stresses.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from functools import lru_cache
from typing import Any

import numpy as np
import xarray as xr

from ..physics.batch_setup import build_batch
from ..physics.design import Design
from ..physics.history_batch import integrate_histories
from ..physics.integration import QOI_INFO, BatchEvaluator
from ..physics.model import ModelSetup
from ..physics.pitch_errors import PitchErrors
from ..physics.rating import RatingSettings, StaticRating, static_rating
from .tooth_loads import GEARS, stress_peaks

#: History samples per mesh period the stresses are read from (the peaks' resolution along the path
#: of contact: 64 places a sample every 1/64 of a base pitch, as the rating analysis does).
STRESS_SAMPLES_PER_PERIOD = 64

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


def _run_qois(setup: ModelSetup, rating: StaticRating, x: np.ndarray, first_period: int, samples: int) -> list[float]:
    peaks = stress_peaks(setup, rating, x, first_period=first_period, samples_per_period=samples)
    names = (name.rsplit("_", 1) for name in STRESS_QOIS)
    return [float(peaks[quantity][GEARS.index(gear)]) for quantity, gear in names]


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
    samples_per_period: int = STRESS_SAMPLES_PER_PERIOD,
    threads: int | None = 1,
) -> xr.Dataset:
    """The tooth stress QoIs of every sample: each run's DTE history turned into root and flank stresses.

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
    samples_per_period : int
        History samples per mesh period.
    threads : int, optional
        Threads of the history integration (None: all cores); the numbers do not depend on it.

    Returns
    -------
    xarray.Dataset
        Dim ``sample``: the variables of :data:`STRESS_QOI_INFO`, Pa.

    Examples
    --------
    At a crawl the pinion's root stress peak is ISO 6336-3's sigma_F at K_v = 1 (within the
    transmission error's own load variation):

    >>> import uqgear
    >>> from uqgear.physics.rating import static_rating
    >>> from uqgear.dynamics.stress_qois import tooth_stress_qois
    >>> design = uqgear.load_design("locomotive")
    >>> samples = uqgear.samples_from_mapping({"pinion_speed": [5.0], "drive_torque": [7000.0]})
    >>> qois = tooth_stress_qois(design, samples, n_periods=30, keep_periods=10)
    >>> iso = static_rating(design, 7000.0, 5.0, dynamic_factor=1.0)
    >>> abs(float(qois["root_stress_peak_pinion"][0]) / iso.root_stress[0] - 1.0) < 0.01
    True
    """
    settings = rating if rating is not None else RatingSettings()
    setups = build_batch(
        design,
        samples,
        effects=effects,
        damping_in_separation=damping_in_separation,
        stiffness=stiffness,
        pitch_errors=pitch_errors,
    )
    runs = integrate_histories(
        setups, n_periods, keep_periods, samples_per_period, steps_per_mode, initial_states, threads=threads
    )
    torques = _operating(samples, "drive_torque", design.operation.drive_torque)
    speeds = np.asarray(samples["pinion_speed"].values, dtype=float)
    first = int(n_periods) - int(keep_periods)
    values = np.array(
        [
            _run_qois(
                setup, _rating(setup.design, float(t), float(n), settings), history[:, 2], first, samples_per_period
            )
            for setup, (history, _), t, n in zip(setups, runs, torques, speeds)
        ]
    ).reshape(len(setups), len(STRESS_QOIS))
    return xr.Dataset(
        {
            name: ("sample", values[:, j], {"units": units, "long_name": text})
            for j, (name, (units, text)) in enumerate(STRESS_QOI_INFO.items())
        },
        coords={"sample": samples["sample"].values} if "sample" in samples.coords else None,
    )


def stress_options(options: Mapping[str, Any]) -> dict[str, Any]:
    """The keyword arguments of :func:`tooth_stress_qois` among batch options (those of
    :func:`~uqgear.physics.integration.simulate_batch`), the others left out.

    Examples
    --------
    >>> stress_options({"n_periods": 60, "threads": 2, "lyapunov": True})
    {'n_periods': 60, 'threads': 2}
    """
    return {key: options[key] for key in _STRESS_OPTION_KEYS if key in options}


#: The batch options that :func:`tooth_stress_qois` takes.
_STRESS_OPTION_KEYS = (
    "n_periods",
    "keep_periods",
    "steps_per_mode",
    "effects",
    "damping_in_separation",
    "stiffness",
    "pitch_errors",
    "threads",
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
        super().__init__(design, **options)
        self.rating = rating

    def __call__(self, samples: xr.Dataset) -> xr.Dataset:
        completed = self.completed(samples)
        result = super().__call__(completed)
        stresses = tooth_stress_qois(self.design, completed, rating=self.rating, **stress_options(vars(self)))
        return result.assign({name: stresses[name].variable for name in STRESS_QOIS})

    def key(self) -> str:
        """:meth:`BatchEvaluator.key` with the stresses' rating inputs."""
        rating = self.rating if self.rating is not None else RatingSettings()
        return repr((super().key(), "tooth_stresses", repr(rating)))


__all__ = [
    "RUN_QOI_INFO",
    "STRESS_QOI_INFO",
    "STRESS_QOIS",
    "STRESS_SAMPLES_PER_PERIOD",
    "StressEvaluator",
    "tooth_stress_qois",
]
