"""The work of one calibration fit on accepted rig features, from the staged box search to the predictive check.

:class:`~uqgear.calibration.estimator.Calibration` checks the settings,
accepts the rig data and keeps the results; what changes while it fits (the
features, once corrected for pitch errors; the current stage's emulated
likelihood; the stages' record) lives in one :class:`PosteriorFit`, whose
steps run in the order of :meth:`Calibration.fit
<uqgear.calibration.estimator.Calibration.fit>`: those of the search for the
posterior's box (:class:`StagedSearch`), then the final sampling and the
predictive check.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import xarray as xr

from ..common.steps import StepLog
from ..uq.seeds import child_seed
from .convergence import ConvergenceCriteria
from .discrepancy import DiscrepancyBasis, DiscrepancyLikelihood
from .discrepancy_results import (
    LOG_UNITS,
    DiscrepancyFit,
    discrepancy_dataset,
    discrepancy_summary,
    fit_discrepancy,
    joint_beta_draws,
)
from .likelihood import Features, StageLikelihood
from .pitch_correction import PitchCorrection, pitch_error_correction
from .predictive import predictive_check
from .sampling import final_sampling, search_box
from .summaries import posterior_dataset, posterior_summary
from .training import ModelRuns, train_emulators


class StagedSearch:
    """Staged emulators, box search and pitch-error correction: the search for the posterior's box of one fit.

    Parameters
    ----------
    features : Features
        The rig's observed features (:func:`~uqgear.calibration.likelihood.observed_features`).
    model : ModelRuns
        The real model at the rig's operating points.
    bounds : mapping
        Name -> (lower, upper) prior bounds of the global parameters.
    prior_lower, prior_upper : numpy.ndarray
        The prior box of the sampled vector (the global parameters, then
        each run's T2), physical units: the first stage's box.
    n_training : int
        Model runs per operating point and emulator stage.
    degree : int
        Total degree of the polynomial emulators.
    walkers : int
        emcee walkers.
    stage_steps, max_stages : int
        Steps per box-finding stage, and most stages.
    error_floor : float
        Lower bound of the model error (:func:`~uqgear.calibration.sampling.search_box`).
    discrepancy : (DiscrepancyBasis, numpy.ndarray) or None
        The discrepancy's basis and tau grid (:mod:`~uqgear.calibration.discrepancy`); None: no discrepancy term.

    Attributes
    ----------
    features : Features
        The features the likelihood uses (corrected by :meth:`correct_pitch_errors` where it applies).
    likelihood : StageLikelihood or None
        The current stage's emulated likelihood (None before the first stage).
    stages : list of dict
        A record of each box stage, appended as the search goes on.
    """

    def __init__(
        self,
        features: Features,
        model: ModelRuns,
        *,
        bounds: Mapping[str, tuple[float, float]],
        prior_lower: np.ndarray,
        prior_upper: np.ndarray,
        n_training: int,
        degree: int,
        walkers: int,
        stage_steps: int,
        max_stages: int,
        error_floor: float,
        discrepancy: tuple[DiscrepancyBasis, np.ndarray] | None = None,
    ) -> None:
        self.features, self.model, self.bounds = features, model, bounds
        self.discrepancy = discrepancy
        self.prior_lower, self.prior_upper = prior_lower, prior_upper
        self.n_training, self.degree, self.walkers = n_training, degree, walkers
        self.stage_steps, self.max_stages, self.error_floor = stage_steps, max_stages, error_floor
        self.n_global, self.n_op = len(model.parameters), len(model.operating["pinion_speed"])
        self.likelihood: StageLikelihood | None = None
        self.stages: list[dict[str, Any]] = []

    def fit_stage(self, box_lower: np.ndarray, box_upper: np.ndarray, seed: np.random.SeedSequence) -> StageLikelihood:
        """Train the emulators in a box and make their likelihood the current one.

        Parameters
        ----------
        box_lower, box_upper : numpy.ndarray
            The stage's box (n_dim,), physical units.
        seed : SeedSequence
            Scrambling of the training design.

        Returns
        -------
        StageLikelihood
        """
        emulators, loo = train_emulators(
            box_lower,
            box_upper,
            seed,
            run_model=self.model,
            n_global=self.n_global,
            n_op=self.n_op,
            n_training=self.n_training,
            degree=self.degree,
        )
        if self.discrepancy is None:
            self.likelihood = StageLikelihood(box_lower, box_upper, emulators, loo, self.features, self.n_global)
        else:
            basis, tau = self.discrepancy
            phi = basis.matrix(self.model.operating["pinion_speed"], self.model.operating["drive_torque"])
            self.likelihood = DiscrepancyLikelihood(
                box_lower, box_upper, emulators, loo, self.features, self.n_global, phi=phi, tau=tau
            )
        return self.likelihood

    def fitted_likelihood(self) -> StageLikelihood:
        """The likelihood of the last search box (the search sets it before anything reads it)."""
        assert self.likelihood is not None, "read before the first search"
        return self.likelihood

    def search(
        self,
        rng: np.random.Generator,
        design_seed: np.random.SeedSequence,
        chain_seed: np.random.SeedSequence,
        start_points: np.ndarray | None = None,
    ) -> tuple[np.ndarray, bool]:
        """The staged box search (:func:`~uqgear.calibration.sampling.search_box`).

        Parameters
        ----------
        rng : numpy.random.Generator
            Draws of walker starts.
        design_seed, chain_seed : SeedSequence
            Parents of each stage's training-design and chain seeds.
        start_points : numpy.ndarray, optional
            Physical points (M, n_dim) to resume from, in the current
            stage's box and on its emulators; None: start in the prior box.

        Returns
        -------
        start_points : numpy.ndarray
            Physical posterior draws of the last stage.
        truncated : bool
            Whether the last stage's posterior is truncated by its box.
        """
        resumed: dict[str, Any] = (
            {} if start_points is None else {"start_likelihood": self.likelihood, "start_points": start_points}
        )
        return search_box(
            self.fit_stage,
            self.prior_lower,
            self.prior_upper,
            used=self.features.used,
            walkers=self.walkers,
            stage_steps=self.stage_steps,
            max_stages=self.max_stages,
            error_floor=self.error_floor,
            rng=rng,
            design_seed=design_seed,
            chain_seed=chain_seed,
            stages=self.stages,
            **resumed,
        )

    def correct_pitch_errors(
        self,
        rig: xr.Dataset,
        points: np.ndarray,
        truncated: bool,
        rng: np.random.Generator,
        seeds: Sequence[np.random.SeedSequence],
        steps: StepLog,
        *,
        channels: Sequence[str],
        draws: int,
        classes: tuple[float, float] | None,
    ) -> tuple[PitchCorrection, np.ndarray, bool]:
        """The pitch-error correction at the medians of posterior draws and, where applied, the box search
        resumed on the corrected features (:mod:`~uqgear.calibration.pitch_correction`).

        Parameters
        ----------
        rig : xarray.Dataset
            The order-tracked campaign.
        points : numpy.ndarray
            Physical posterior draws (M, n_dim) of the box search.
        truncated : bool
            Whether their posterior is truncated by the box.
        rng : numpy.random.Generator
            Draws of walker starts of the resumed search.
        seeds : sequence of SeedSequence
            Three: the pitch-error draws', then the resumed search's training-design and chain seeds.
        steps : StepLog
            Gets the correction step and, where it applies, the resumed search.
        channels : sequence of str
            Rig channels of the likelihood.
        draws : int
            Random pitch-error draws the correction averages.
        classes : (float, float) or None
            ISO 1328-1 flank tolerance classes of the rig's gears (None: read from the sidebands).

        Returns
        -------
        correction : PitchCorrection
        start_points : numpy.ndarray
            The draws to start the final sampling from (``points`` where not applied).
        truncated : bool
        """
        with steps.step("pitch-error correction (rig sidebands, model draws at the posterior medians)") as found:
            medians = np.median(points, axis=0)
            correction = pitch_error_correction(
                rig,
                self.model.design,
                self.features,
                dict(zip(self.model.parameters, medians[: self.n_global])),
                medians[self.n_global :],
                seed=seeds[0],
                effects=self.model.effects,
                channels=channels,
                n_harmonics=self.model.n_harmonics,
                draws=draws,
                classes=classes,
            )
            found.update(applied=correction.applied, reason=correction.reason)
        if not correction.applied:
            return correction, points, truncated
        with steps.step("search the posterior box again (corrected features)") as found:
            self.features = correction.apply(self.features)
            # resumed in the last box, on its emulators: only the features changed
            self.likelihood = self.fitted_likelihood().with_features(self.features)
            points, truncated = self.search(rng, seeds[1], seeds[2], start_points=points)
            found.update(stages=self.stages, truncated=truncated)
        return correction, points, truncated


class PosteriorFit(StagedSearch):
    """One fit: the staged search (:class:`StagedSearch`, whose parameters it takes), the final sampling on its
    last stage's emulators and the posterior predictive check.

    Attributes
    ----------
    discrepancy_fit : DiscrepancyFit or None
        The fitted discrepancy (set by :meth:`final_sampling` with a discrepancy term).
    """

    discrepancy_fit: DiscrepancyFit | None = None

    def final_sampling(
        self,
        start_points: np.ndarray,
        rng: np.random.Generator,
        seed: np.random.SeedSequence,
        truncated: bool,
        *,
        criteria: ConvergenceCriteria,
        chunk_steps: int,
        max_steps: int,
    ) -> tuple[dict[str, Any], xr.Dataset, dict[str, Any]]:
        """The final run on the last stage's emulators (:func:`~uqgear.calibration.sampling.final_sampling`).

        Parameters
        ----------
        start_points : numpy.ndarray
            Physical draws (M, n_dim) the walkers start from and the independence proposals are fitted to.
        rng : numpy.random.Generator
            Draws of walker starts.
        seed : SeedSequence
            The sampler's.
        truncated : bool
            Whether the last stage's posterior is truncated by its box.
        criteria : ConvergenceCriteria
        chunk_steps, max_steps : int
            Steps per chunk, and most steps.

        Returns
        -------
        diagnostics : dict
            The convergence verdict and diagnostics.
        posterior : xarray.Dataset
            :func:`~uqgear.calibration.summaries.posterior_dataset`.
        summary : dict
            :func:`~uqgear.calibration.summaries.posterior_summary`.
        """
        names = list(self.model.parameters) + [f"adhesion_torque[{op}]" for op in range(self.n_op)]
        verdict, physical, log_likelihood = final_sampling(
            self.fitted_likelihood(),
            start_points,
            rng,
            seed,
            walkers=self.walkers,
            chunk_steps=chunk_steps,
            max_steps=max_steps,
            criteria=criteria,
            names=names,
            truncated=truncated,
            # with the discrepancy the per-run T2 carry little information and fill their prior intervals
            # (docs/validation/calibration.md, "Model discrepancy")
            in_box=self.discrepancy is not None,
        )
        parameters, operating = self.model.parameters, self.model.operating
        posterior = posterior_dataset(
            physical,
            log_likelihood,
            parameters=parameters,
            bounds=self.bounds,
            operating=operating,
            converged=bool(verdict["converged"]),
        )
        summary = posterior_summary(
            physical,
            parameters=parameters,
            bounds=self.bounds,
            operating=operating,
            likelihood=self.fitted_likelihood(),
            features=self.features,
        )
        likelihood = self.fitted_likelihood()
        if self.discrepancy is not None and isinstance(likelihood, DiscrepancyLikelihood):
            unit = likelihood.to_unit(physical.reshape(-1, likelihood.n_dim))
            self.discrepancy_fit = fit_discrepancy(unit, likelihood, self.features, self.discrepancy[0])
            summary["discrepancy"] = discrepancy_summary(
                self.discrepancy_fit, self.features, likelihood.loo_rms, operating
            )
            extra = discrepancy_dataset(self.discrepancy_fit, operating)
            # one draw of beta with each posterior draw, so that a prediction carries the discrepancy that goes
            # with the draw's parameters (joint_beta_draws)
            beta = joint_beta_draws(unit, likelihood, np.random.default_rng(child_seed(seed, 1)))
            n_channels, n_harmonics = likelihood.shape[1:]
            beta = beta.reshape(*physical.shape[:2], n_channels, n_harmonics, -1).transpose(1, 0, 2, 3, 4)
            extra["discrepancy_beta"] = (
                ("chain", "draw", "channel", "harmonic", "basis"),
                beta,
                {"units": LOG_UNITS, "long_name": "discrepancy coefficients drawn with each posterior draw"},
            )
            posterior = xr.merge([posterior, extra], combine_attrs="no_conflicts")
        return verdict, posterior, summary

    def predictive_check(
        self, posterior: xr.Dataset, summary: Mapping[str, Any], rng: np.random.Generator, *, draws: int
    ) -> tuple[xr.Dataset, dict[str, Any]]:
        """The posterior predictive check (:func:`~uqgear.calibration.predictive.predictive_check`).

        Parameters
        ----------
        posterior : xarray.Dataset
            The final sampling's draws.
        summary : mapping
            Its summary (the model error levels are read).
        rng : numpy.random.Generator
            Chooses the draws.
        draws : int
            Posterior draws rerun with the real model.

        Returns
        -------
        predictive : xarray.Dataset
        check : dict
        """
        return predictive_check(
            posterior,
            rng,
            parameters=self.model.parameters,
            draws=draws,
            features=self.features,
            likelihood=self.fitted_likelihood(),
            model_error=summary["model_error"],
            pinion_speed=self.model.operating["pinion_speed"],
            run_model=self.model,
            discrepancy=self._discrepancy_at_runs(),
        )

    def _discrepancy_at_runs(self) -> tuple[np.ndarray, np.ndarray] | None:
        """The fitted discrepancy's posterior mean and standard deviation at the runs (None without one)."""
        if self.discrepancy_fit is None:
            return None
        fitted, operating = self.discrepancy_fit.discrepancy, self.model.operating
        speed, torque = operating["pinion_speed"], operating["drive_torque"]
        return fitted.mean_at(speed, torque), fitted.sd_at(speed, torque)
