"""The fitted model as a function of an optimiser vector: the nominal model plus any candidate effects.

:class:`FitProblem` turns an optimiser vector (global parameters, each
run's T2 position) into model features, standardised discrepancies and the
residuals the robust fits minimise (:mod:`.fitting`).
"""

from __future__ import annotations

import copy
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from .candidates import Candidate, ParameterSpec, check_combination, combined_periodicity, nominal_parameters
from .case import RigCase
from .discrepancy import standardised_discrepancy
from .execution import RunTask

# Feature kinds the fits use (RMS and kurtosis enter the gap map only).
FITTED_KINDS = ("line", "band")
# Robust (Cauchy) loss of the fits: quadratic to about this |z|, then logarithmic.
LOSS_SCALE = 3.0
# Finite-difference step in optimiser units (prior standard deviations or effect units).
_DIFFERENCE_STEP = 0.02


class FitProblem:
    """Nominal model plus any number of candidate effects, as a function of an optimiser vector.

    The vector holds the global parameters (nominal ones, then each
    candidate's, in order) in optimiser units (:class:`ParameterSpec`), then
    the position of each run's T2 inside its interval (0 at the lower, 1 at
    the upper bound). All candidates act together in every simulation; the
    last one is the *new* candidate a fit adds to the others (its ``base``,
    fixed in structure, their parameters fitted or held), the one a score
    is about.

    Parameters
    ----------
    case : RigCase
    candidates : Candidate or sequence of Candidate or None
        The effects of the model (None or empty: the nominal model); each
        library effect at most once (:func:`~.candidates.check_combination`).
    model_error : mapping, optional
        This model's own model error (e.g. with the pitch-error allowance
        of its own effects, :func:`~.allowances.pitch_errors.allowance_for_fit`);
        default the case's.
    """

    def __init__(
        self,
        case: RigCase,
        candidates: Candidate | Sequence[Candidate] | None,
        *,
        model_error: Mapping[str, float] | None = None,
    ) -> None:
        self.case = case
        self.own_model_error = model_error
        if candidates is None:
            candidates = ()
        elif isinstance(candidates, Candidate):
            candidates = (candidates,)
        self.candidates: tuple[Candidate, ...] = check_combination(candidates)
        self.specs: list[ParameterSpec] = nominal_parameters(case.design)
        for candidate in self.candidates:
            self.specs += list(candidate.fitted)
        self.n_global = len(self.specs)
        # where the new candidate's parameters start: the base's (nominal and earlier effects) end there
        self.n_base_global = self.n_global - (len(self.candidate.fitted) if self.candidate else 0)
        self.size = self.n_global + case.n_op
        # RMS and kurtosis sum up everything, also what the model class cannot produce; fitted to
        # them the nominal parameters would trade mesh-harmonic accuracy for the unmodelled part.
        fitted_kind = np.array([kind in FITTED_KINDS for kind in case.layout.kinds])
        self.mask = case.mask() & fitted_kind
        self.periodicity = combined_periodicity([c.periodicity for c in self.candidates], case.design)
        lower = [spec.bounds()[0] for spec in self.specs] + [0.0] * case.n_op
        upper = [spec.bounds()[1] for spec in self.specs] + [1.0] * case.n_op
        self.lower = np.array(lower)
        self.upper = np.array(upper)
        self.prior_index = np.array([i for i, spec in enumerate(self.specs) if spec.prior], dtype=int)
        self._cache: dict[tuple[Any, ...], tuple[np.ndarray, bool]] = {}
        self.evaluations = 0

    def with_model_error(self, model_error: Mapping[str, float] | None) -> FitProblem:
        """The same model judged with another model error (its own pitch-error allowance).

        The two share their simulations: the model error changes no run, only how its features are scored.
        """
        sibling = copy.copy(self)
        sibling.own_model_error = model_error
        return sibling

    def on_case(self, case: RigCase) -> FitProblem:
        """The same model on a case that differs only in its model error (an allowance taken in).

        The two share their simulations, as :meth:`with_model_error`.
        """
        sibling = copy.copy(self)
        sibling.case = case
        return sibling

    @property
    def candidate(self) -> Candidate | None:
        """The new candidate (the last one), or None for the nominal model."""
        return self.candidates[-1] if self.candidates else None

    @property
    def base(self) -> tuple[Candidate, ...]:
        """The candidates the new one is added to."""
        return self.candidates[:-1]

    # -- vectors
    def vector(
        self, values: Mapping[str, float], t2_position: Sequence[float] | np.ndarray | float = 0.5
    ) -> np.ndarray:
        """Optimiser vector from natural values (missing globals at their centres)."""
        v = np.zeros(self.size)
        for i, spec in enumerate(self.specs):
            if spec.name in values:
                v[i] = spec.to_optimiser(float(values[spec.name]))
        v[self.n_global :] = np.broadcast_to(np.asarray(t2_position, dtype=float), (self.case.n_op,))
        return np.clip(v, self.lower, self.upper)

    def values(self, v: np.ndarray) -> dict[str, float]:
        """Natural values of the global parameters."""
        return {spec.name: spec.from_optimiser(float(v[i])) for i, spec in enumerate(self.specs)}

    def adhesion_torques(self, v: np.ndarray) -> np.ndarray:
        position = np.clip(v[self.n_global :], 0.0, 1.0)
        return self.case.adhesion_lower + position * (self.case.adhesion_upper - self.case.adhesion_lower)

    # -- model features
    def run_task(self, v: np.ndarray, op: int) -> RunTask:
        """The simulation of run ``op`` at optimiser vector ``v``."""
        values = self.values(v)
        design = self.case.design.replace(
            zeta_mesh=values["zeta_mesh"], ste_amplitude=values["ste_amplitude"], k1=values["k1"], k2=values["k2"]
        )
        effects = tuple(candidate.make(values) for candidate in self.candidates)
        return RunTask(
            op,
            design,
            values["mesh_stiffness_scale"],
            float(self.adhesion_torques(v)[op]),
            effects,
            self.periodicity,
            tracked=self.tracked,
        )

    @property
    def tracked(self) -> bool:
        """Whether this model's runs are read through the rig's order tracking.

        :attr:`~uqgear.diagnosis.case.RigCase.reads_tracked` of its case.
        """
        return self.case.reads_tracked

    def model_features(
        self, vectors: Sequence[np.ndarray], ops: Sequence[Sequence[int]] | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """Noise-free model features (V, n_op, n_channel, all features), NaN for runs not asked.

        Returns the features and whether each run's response was periodic
        (V, n_op). Runs already simulated for the same parameters come from a
        cache; the others are simulated together (in worker processes when
        the case has them).
        """
        case = self.case
        n_all = case.observed_all.shape[-1]
        out = np.full((len(vectors), case.n_op, len(case.channels), n_all), np.nan)
        periodic = np.zeros((len(vectors), case.n_op), dtype=bool)
        tasks: list[RunTask] = []
        where: list[tuple[int, int, tuple[Any, ...]]] = []
        # runs simulated before the reading changed (the nominal fit, before the pitch-error allowance)
        # serve only where no record was resampled: there both readings are the same
        reading = self.tracked and any(image is not None for image in case.tracking)
        for index, v in enumerate(vectors):
            for op in range(case.n_op) if ops is None else ops[index]:
                key = (op, reading, float(v[self.n_global + op]), *np.round(v[: self.n_global], 12))
                if key in self._cache:
                    out[index, op], periodic[index, op] = self._cache[key]
                    continue
                tasks.append(self.run_task(v, op))
                where.append((index, op, key))
        for (index, op, key), (values, is_periodic) in zip(where, case.execute(tasks)):
            self.evaluations += 1
            out[index, op], periodic[index, op] = values, is_periodic
            self._cache[key] = (values, is_periodic)
        return out, periodic

    @property
    def model_error(self) -> Mapping[str, float]:
        """The model error the discrepancies are standardised with: this model's own, else the case's."""
        return self.case.model_error if self.own_model_error is None else self.own_model_error

    def discrepancy(
        self, model_all: np.ndarray, model_error: Mapping[str, float] | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """Standardised discrepancies and scales (..., n_op, n_channel, F) of model features.

        ``model_error`` replaces :attr:`model_error` (e.g. to judge a base model by a richer one's error).
        """
        case = self.case
        return standardised_discrepancy(
            case.observed,
            model_all[..., case.layout.columns],
            case.noise_std,
            case.noise,
            case.layout,
            self.model_error if model_error is None else model_error,
            band_noise_std=case.band_noise_std,
        )

    def residual_vector(self, z: np.ndarray, v: np.ndarray) -> np.ndarray:
        """Feature residuals (masked) followed by the prior residuals."""
        values = np.where(np.isfinite(z), z, 0.0)[self.mask]
        return np.concatenate([values, v[self.prior_index]])

    def residuals(self, v: np.ndarray) -> np.ndarray:
        model, _ = self.model_features([v])
        z, _ = self.discrepancy(model[0])
        return self.residual_vector(z, v)

    def jacobian(self, v: np.ndarray, free: np.ndarray) -> np.ndarray:
        """Forward-difference Jacobian of :meth:`residuals` in the ``free`` entries of ``v``.

        All perturbations are simulated in one batch. Each run depends only
        on its own T2, so one perturbation of all T2 positions at once gives
        every run's T2 column (the positions are free all together or not at all).
        """
        free_index = np.flatnonzero(free)
        global_index = free_index[free_index < self.n_global]
        t2_free = bool(np.any(free_index >= self.n_global))
        vectors = [v]
        steps = []
        for i in global_index:
            step = _DIFFERENCE_STEP if v[i] + _DIFFERENCE_STEP <= self.upper[i] else -_DIFFERENCE_STEP
            shifted = v.copy()
            shifted[i] += step
            vectors.append(shifted)
            steps.append(step)
        if t2_free:
            t2_step = np.where(v[self.n_global :] + _DIFFERENCE_STEP <= 1.0, _DIFFERENCE_STEP, -_DIFFERENCE_STEP)
            shifted = v.copy()
            shifted[self.n_global :] += t2_step
            vectors.append(shifted)
        model, _ = self.model_features(vectors)
        z, _ = self.discrepancy(model)
        base = self.residual_vector(z[0], v)
        columns = {}
        for k, (i, step) in enumerate(zip(global_index, steps), start=1):
            columns[int(i)] = (self.residual_vector(z[k], vectors[k]) - base) / step
        if t2_free:
            change = self.residual_vector(z[-1], vectors[-1]) - base
            rows_of = self.op_of_row()
            for op in range(self.case.n_op):
                column = np.zeros(base.size)
                rows = rows_of == op
                column[rows] = change[rows] / t2_step[op]
                columns[self.n_global + op] = column
        return np.stack([columns[int(i)] for i in free_index], axis=1)

    def op_of_row(self) -> np.ndarray:
        """Run index of each residual row (-1 for priors)."""
        shape = self.mask.shape
        ops = np.broadcast_to(np.arange(shape[0])[:, None, None], shape)[self.mask]
        return np.concatenate([ops, np.full(self.prior_index.size, -1)])


def robust_cost(residuals: np.ndarray) -> float:
    """The fits' objective: the Cauchy loss 0.5 c^2 sum log(1 + (r/c)^2), c = :data:`LOSS_SCALE`.

    A redescending loss: a feature far beyond what the model class can
    produce (an unmodelled line thousands of sigmas high) loses its pull on
    the parameters instead of bending them towards it through tiny slopes.
    """
    s = (np.asarray(residuals) / LOSS_SCALE) ** 2
    return float(0.5 * LOSS_SCALE**2 * np.sum(np.log1p(s)))


def robust_weights(residuals: np.ndarray) -> np.ndarray:
    """IRLS weights of the Cauchy loss: 1 / (1 + (r/c)^2)."""
    return 1.0 / (1.0 + (np.asarray(residuals) / LOSS_SCALE) ** 2)


__all__ = ["FitProblem", "robust_cost", "robust_weights", "LOSS_SCALE", "FITTED_KINDS"]
