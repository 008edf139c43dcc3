"""Real model runs at calibration points, and the per-run emulators trained on them in a box.

Each run's 3 x ``n_harmonics`` log features depend on the global parameters
and that run's T2 only, so each run gets one total-degree polynomial
emulator fitted by least squares on a scrambled Sobol design of real model
runs inside the box.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence

import numpy as np
import xarray as xr
from scipy.stats import qmc

from ..physics.design import Design
from ..physics.effects import Effect
from .emulator import PolynomialEmulator
from .errors import CalibrationError
from .harmonics import HARMONIC_CHANNELS, model_harmonics


def model_inputs(
    physical: np.ndarray, parameters: Sequence[str], pinion_speed: float, drive_torque: float
) -> xr.Dataset:
    """Model sample variables of one run at physical points (M, n_global + 1): the globals, then T2."""
    values: dict[str, np.ndarray] = {
        "pinion_speed": np.full(physical.shape[0], pinion_speed),
        "drive_torque": np.full(physical.shape[0], drive_torque),
        "adhesion_torque": physical[:, -1],
    }
    for index, name in enumerate(parameters):
        values[name] = physical[:, index]
    return xr.Dataset({name: ("sample", array) for name, array in values.items()})


def model_log_features(
    points: Sequence[np.ndarray],
    *,
    design: Design,
    parameters: Sequence[str],
    operating: Mapping[str, np.ndarray],
    effects: Sequence[Effect],
    n_harmonics: int,
    transient: float,
    window: float,
    threads: int | None,
) -> np.ndarray:
    """Log features (op, M, channel, harmonic) at physical points (M, n_global + 1) per run.

    The runs go in one parallel batch, ordered point by point so that the
    runs sharing a design follow each other (the model caches its
    stiffness tables per design).
    """
    n_op = len(operating["pinion_speed"])
    count = points[0].shape[0]
    inputs = [
        model_inputs(points[op], parameters, operating["pinion_speed"][op], operating["drive_torque"][op])
        for op in range(n_op)
    ]
    samples = xr.concat(inputs, dim="sample")
    order = np.arange(count * n_op).reshape(n_op, count).T.ravel()
    result = model_harmonics(
        design,
        samples.isel(sample=order),
        effects=effects,
        n_harmonics=n_harmonics,
        transient=transient,
        window=window,
        threads=threads,
    )
    with np.errstate(divide="ignore"):
        values = np.log(result["amplitude"].values)
    restored = np.empty_like(values)
    restored[order] = values
    return restored.reshape(n_op, count, len(HARMONIC_CHANNELS), n_harmonics)


class ModelRuns:
    """The real model of one calibration (:func:`model_log_features` with its settings), counting its runs.

    Parameters
    ----------
    design : Design
        The nominal design.
    parameters : sequence of str
        The global parameters, in the order of the points' columns.
    operating : mapping
        Speed, drive torque and T2 interval of each run
        (:func:`~uqgear.calibration.likelihood.operating_points`).
    effects : sequence of Effect
        Model extensions with fixed parameters.
    n_harmonics : int
        Mesh harmonics per channel.
    transient, window : float
        Settings of :func:`~uqgear.calibration.harmonics.model_harmonics` (s).
    threads : int or None
        Threads of the model runs (None: all cores).

    Attributes
    ----------
    count : int
        Model runs so far (one per operating point and physical point).
    """

    def __init__(
        self,
        *,
        design: Design,
        parameters: Sequence[str],
        operating: Mapping[str, np.ndarray],
        effects: Sequence[Effect],
        n_harmonics: int,
        transient: float,
        window: float,
        threads: int | None,
    ) -> None:
        self.design, self.parameters, self.operating = design, parameters, operating
        self.effects, self.n_harmonics = effects, n_harmonics
        self.transient, self.window, self.threads = transient, window, threads
        self.count = 0

    def __call__(self, points: Sequence[np.ndarray]) -> np.ndarray:
        """Log features (op, M, channel, harmonic) at physical points (M, n_global + 1) per run."""
        values = model_log_features(
            points,
            design=self.design,
            parameters=self.parameters,
            operating=self.operating,
            effects=self.effects,
            n_harmonics=self.n_harmonics,
            transient=self.transient,
            window=self.window,
            threads=self.threads,
        )
        self.count += values.shape[0] * values.shape[1]
        return values


def train_emulators(
    box_lower: np.ndarray,
    box_upper: np.ndarray,
    seed: np.random.SeedSequence,
    *,
    run_model: Callable[[list[np.ndarray]], np.ndarray],
    n_global: int,
    n_op: int,
    n_training: int,
    degree: int,
) -> tuple[list[PolynomialEmulator], np.ndarray]:
    """Emulators of each run's log features in a box, and their leave-one-out RMS errors (op, features).

    ``run_model`` gives the log features (op, M, channel, harmonic) at
    physical points (M, n_global + 1) per run (:func:`model_log_features`).
    """
    n_terms = PolynomialEmulator(n_global + 1, degree).n_terms
    if n_training <= n_terms:
        raise CalibrationError(
            f"n_training: {n_training} runs per operating point do not determine "
            f"{n_terms} polynomial terms (degree {degree} in {n_global + 1} "
            f"inputs); raise n_training or lower emulator_degree"
        )
    sobol = qmc.Sobol(n_global + 1, scramble=True, seed=np.random.default_rng(seed))
    unit = sobol.random_base2(int(round(math.log2(n_training))))
    points = []
    for op in range(n_op):
        columns = list(range(n_global)) + [n_global + op]
        # clipped: the arithmetic can round past the box, whose sides may be the design's own limits
        points.append(
            np.clip(
                box_lower[columns] + unit * (box_upper[columns] - box_lower[columns]),
                box_lower[columns],
                box_upper[columns],
            )
        )
    outputs = run_model(points).reshape(n_op, n_training, -1)
    emulators, loo = [], np.full((n_op, outputs.shape[2]), np.nan)
    z = 2.0 * unit - 1.0
    for op in range(n_op):
        values = outputs[op]
        finite = np.all(np.isfinite(values), axis=1)
        if finite.sum() <= n_terms:
            raise CalibrationError(
                f"operating point {op}: only {finite.sum()} of {values.shape[0]} model runs gave finite features"
            )
        emulator = PolynomialEmulator(n_global + 1, degree).fit(z[finite], values[finite])
        emulators.append(emulator)
        loo[op] = emulator.loo_rms_
    return emulators, loo
