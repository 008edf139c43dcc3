"""The Calibration estimator: settings checked in ``__init__``, the work in ``fit``, results in ``*_`` attributes.

``fit`` accepts the rig data (:mod:`~uqgear.calibration.rig_input`) and prepares the features and the prior
box; the staged search, the pitch-error correction, the final sampling and the predictive check run on a
:class:`~uqgear.calibration.posterior_fit.PosteriorFit`. The estimator's ``__init__`` and its settings record are
those of :class:`~uqgear.calibration.settings.CalibrationSettings`; the readers of the fitted state
(:meth:`~uqgear.calibration.record.CalibrationRecord.to_dict`, ...) those of
:class:`~uqgear.calibration.record.CalibrationRecord`.
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass

import numpy as np
import xarray as xr

from ..common.steps import StepLog
from ..physics.design import Design
from ..uq.seeds import child_seed
from .convergence import ConvergenceCriteria
from .discrepancy import DiscrepancyBasis, tau_grid
from .likelihood import Features, observed_features, operating_points, prior_box
from .posterior_fit import PosteriorFit
from .priors import prior_bounds
from .record import CalibrationRecord
from .rig_input import accept_rig
from .sampling import walker_count
from .training import ModelRuns


@dataclass(frozen=True)
class _Campaign:
    """A rig campaign as the fit reads it: the data (order-tracked where needed), the nominal design, the
    observed features, and the seconds order tracking took."""

    rig: xr.Dataset
    design: Design
    features: Features
    tracking_s: float


class Calibration(CalibrationRecord):
    """Bayesian calibration of the gear model on rig data (settings here; :meth:`fit` does the work).

    Parameters
    ----------
    parameters : sequence of str
        Global parameters (:mod:`uqgear.calibration`); default
        ``mesh_stiffness_scale, zeta_mesh, backlash, ste_amplitude, k1, k2``.
    design : Design, optional
        Nominal design; default the rig file's ``design`` attribute. When
        given it replaces the file's, which is then not validated as a design.
    priors : mapping, optional
        Name -> (lower, upper) uniform prior bounds replacing the defaults.
    channels : sequence of str
        Rig channels whose mesh harmonics enter the likelihood.
    n_harmonics : int
        Mesh harmonics per channel.
    min_snr : float
        Features with observed amplitude / noise std below this are left out.
    model_error_range : (float, float)
        Bounds of the log-uniform prior of the relative model error per
        (channel, harmonic) group.
    effects : sequence of Effect
        Model extensions with fixed parameters (none for a healthy rig).
    n_training : int
        Model runs per operating point and emulator stage (a power of 2).
    emulator_degree : int
        Total degree of the polynomial emulators.
    max_stages : int
        Most emulator boxes fitted.
    n_walkers : int, optional
        emcee walkers; default 4 x the number of sampled dimensions (even).
    stage_steps : int
        Steps per box-finding stage.
    chunk_steps, max_steps : int
        The final stage (the ensemble moves plus independence proposals
        fitted to the last box stage's draws) runs in chunks until converged
        or ``max_steps``; its first tenth is burn-in.
    autocorr_factor, rhat_threshold, min_ess : float
        Convergence criteria (:mod:`~uqgear.calibration.convergence`).
    predictive_draws : int
        Posterior draws rerun with the real model.
    transient, window : float
        Settings of :func:`model_harmonics` (s).
    seed : SeedSequence or int, optional
        Source of all randomness (Sobol scrambling, emcee, predictive draws).
    threads : int, optional
        Threads of the model runs (default: all cores).
    pitch_correction : bool
        Correct the observed mesh harmonics for the rig's pitch errors where
        its sidebands show them (:mod:`~uqgear.calibration.pitch_correction`;
        nothing changes where they show none).
    pitch_draws : int
        Random pitch-error draws the correction averages (at least 2).
    pitch_classes : (float, float) or None
        ISO 1328-1 flank tolerance classes of the rig's gears (from their
        drawings; default 6 to 8, the usual traction-gear grades); None:
        the level read from the rig's sidebands instead.
    discrepancy : bool
        Add a model-discrepancy function of the operating point per
        (channel, harmonic) group to the likelihood, integrated out
        analytically (:mod:`~uqgear.calibration.discrepancy`): for campaigns
        whose physics the model does not have; the final run's independence
        proposals are then restricted to the box (the same posterior,
        sampled with fewer rejections). Off, every result is that of the
        ordinary calibration.
    discrepancy_range : (float, float)
        Bounds of the log-uniform part of the prior of the discrepancy's
        scale tau (standard deviation of each basis coefficient,
        log-amplitude units); the other half of the prior is tau = 0, no
        discrepancy in the group (:mod:`~uqgear.calibration.discrepancy`).

    Attributes
    ----------
    posterior_ : xarray.Dataset
        Draws over (chain, draw): one variable per parameter (design-key
        names, SI units), ``adhesion_torque`` over (chain, draw, op),
        ``log_likelihood``.
    summary_ : dict
        Per parameter mean, sd, q05, q50, q95, prior, units; per run T2; the
        model error per group.
    diagnostics_ : dict
        Convergence diagnostics and their verdict.
    converged_ : bool
    predictive_ : xarray.Dataset
        Posterior predictive check over (op, channel, harmonic).
    predictive_check_ : dict
        Its summary.
    emulator_ : dict
        Stages, boxes and leave-one-out errors of the emulators.
    timing_ : dict
        Wall and CPU time of the fit, s; model runs; the time of order
        tracking, of the pitch-error correction and of each step (``steps_s``).
    steps_ : StepLog
        The steps of the fit as they finished (kept by a failure).
    pitch_errors_ : PitchCorrection or None
        The pitch-error correction (None when switched off).
    discrepancy_ : Discrepancy or None
        The fitted discrepancy (None without ``discrepancy``); the summary's
        ``discrepancy`` entry has tau per group, delta at each run and each
        channel's variance shares; :meth:`discrepancy_at` draws it at new
        operating points.

    Examples
    --------
    A virtual rig whose mesh is 10 % stiffer than the nominal design's; a
    small calibration of that one factor (a short run, small emulator and
    chains; the defaults are sized for real campaigns) holds the truth in
    its 90 % interval:

    >>> import uqgear
    >>> design = uqgear.load_design("locomotive")
    >>> rig = uqgear.simulate_campaign(design, {"pinion_speed": [2200.0], "drive_torque": [7000.0]},
    ...                                true_parameters={"mesh_stiffness_scale": 1.1}, seed=5,
    ...                                duration=0.2, run_in=0.2)
    >>> calibration = uqgear.Calibration(["mesh_stiffness_scale"], n_training=32, emulator_degree=2, max_stages=1,
    ...                                  stage_steps=200, chunk_steps=500, max_steps=2000, predictive_draws=2,
    ...                                  pitch_correction=False, seed=1).fit(rig)
    >>> calibration.converged_
    True
    >>> estimate = calibration.summary_["parameters"]["mesh_stiffness_scale"]
    >>> estimate["prior"], estimate["q05"] < 1.1 < estimate["q95"]
    ([0.7, 1.3], True)
    >>> calibration.posterior_["mesh_stiffness_scale"].dims
    ('chain', 'draw')
    >>> try:
    ...     uqgear.Calibration(["stiffness"])
    ... except uqgear.UqgearError as error:
    ...     print(type(error).__name__)
    CalibrationError
    """

    # ------------------------------------------------------------------ fit

    def fit(self, rig: xr.Dataset | str | os.PathLike[str]) -> Calibration:
        """Calibrate on a rig campaign.

        Parameters
        ----------
        rig : xarray.Dataset or path
            ``uqgear-rig/1`` data (a Dataset is validated, a path read).

        Returns
        -------
        Calibration
            ``self``, with the fitted attributes set.

        Raises
        ------
        RigDataError
            The rig data do not follow the format, or carry no usable signal
            (:func:`~uqgear.rig.usability.check_usable_signal`).
        CalibrationError
            No usable feature, or a setting that does not fit the data.
        InternalError
            A step failed after the input was accepted (``steps_`` holds the
            finished ones).
        """
        wall_start, cpu_start = time.perf_counter(), time.process_time()
        campaign = self._read_campaign(rig)
        # children derived from the spawn key, so that fitting again repeats the run exactly
        seeds = [child_seed(self.seed, index) for index in range(8)]
        # from here on the input is accepted: a failure is ours, reported with its step
        self.steps_ = steps = StepLog()
        stage_rng = np.random.default_rng(seeds[0])
        model, work = _posterior_fit(self, campaign)
        self.emulator_ = {"stages": work.stages}
        with steps.step("search the posterior box (staged emulators and sampling)") as found:
            start_points, truncated = work.search(stage_rng, seeds[1], seeds[2])
            found.update(stages=work.stages, truncated=truncated)
        self.pitch_errors_ = None
        if self.pitch_correction:
            self.pitch_errors_, start_points, truncated = work.correct_pitch_errors(
                campaign.rig,
                start_points,
                truncated,
                stage_rng,
                seeds[5:8],
                steps,
                channels=self.channels,
                draws=self.pitch_draws,
                classes=self.pitch_classes,
            )
        with steps.step("final sampling") as found:
            self.diagnostics_, self.posterior_, self.summary_ = work.final_sampling(
                start_points,
                stage_rng,
                seeds[3],
                truncated,
                chunk_steps=self.chunk_steps,
                max_steps=self.max_steps,
                criteria=ConvergenceCriteria(self.autocorr_factor, self.rhat_threshold, self.min_ess),
            )
            self.converged_ = bool(self.diagnostics_["converged"])
            found.update(converged=self.converged_)
            self.discrepancy_ = None if work.discrepancy_fit is None else work.discrepancy_fit.discrepancy
        with steps.step("posterior predictive check"):
            self.predictive_, self.predictive_check_ = work.predictive_check(
                self.posterior_, self.summary_, np.random.default_rng(seeds[4]), draws=self.predictive_draws
            )
        self._keep_fitted(work, model.count)
        self.timing_ = {
            "wall_s": time.perf_counter() - wall_start,
            "cpu_s": time.process_time() - cpu_start,
            "model_runs": int(self.model_runs_),
            "order_tracking_s": campaign.tracking_s,
            "pitch_correction_s": 0.0 if self.pitch_errors_ is None else self.pitch_errors_.seconds,
            # each step's wall time, in order (the box search, any correction, sampling, the check)
            "steps_s": {entry["step"]: entry["seconds"] for entry in steps.finished},
        }
        return self

    def _read_campaign(self, rig: xr.Dataset | str | os.PathLike[str]) -> _Campaign:
        """Accept the rig data and read their features, operating points and the prior box (input: errors are
        the user's)."""
        accepted = accept_rig(rig, self.design)
        self.rig_source_, self.design_, self.speed_ = accepted.source, accepted.design, accepted.speed
        # the data's features and the prior box are input: a problem with them is the user's (exit 2)
        features = observed_features(
            accepted.rig,
            accepted.design,
            channels=self.channels,
            n_harmonics=self.n_harmonics,
            min_snr=self.min_snr,
            model_error_range=self.model_error_range,
        )
        self.observed_, self.used_, self.model_error_grid_ = features.observed, features.used, features.model_error_grid
        self.n_op_, self.operating_ = accepted.rig.sizes["op"], operating_points(accepted.rig)
        self.bounds_ = prior_bounds(accepted.design, self.parameters, self.priors)
        self.prior_lower_, self.prior_upper_ = prior_box(self.bounds_, self.parameters, self.operating_)
        self.n_global_ = len(self.parameters)
        self.n_dim_ = self.n_global_ + self.n_op_
        return _Campaign(accepted.rig, accepted.design, features, accepted.tracking_s)

    def _keep_fitted(self, work: PosteriorFit, model_runs: int) -> None:
        """Keep the features and likelihood the fit ended with, and the model runs it took."""
        # read at the end: the pitch-error correction may replace the features, and its resumed search the box
        features, likelihood = work.features, work.fitted_likelihood()
        self._features, self._likelihood = features, likelihood
        self.log_observed_, self.noise_variance_ = features.log_observed, features.noise_variance
        self.box_lower_, self.box_upper_, self.loo_rms_ = likelihood.box_lower, likelihood.box_upper, likelihood.loo_rms
        self.model_runs_ = model_runs


def _posterior_fit(calibration: Calibration, campaign: _Campaign) -> tuple[ModelRuns, PosteriorFit]:
    """The model runs of the campaign and the staged posterior fit that drives them."""
    operating = calibration.operating_
    model = ModelRuns(
        design=campaign.design,
        parameters=calibration.parameters,
        operating=operating,
        effects=calibration.effects,
        n_harmonics=calibration.n_harmonics,
        transient=calibration.transient,
        window=calibration.window,
        threads=calibration.threads,
    )
    work = PosteriorFit(
        campaign.features,
        model,
        bounds=calibration.bounds_,
        prior_lower=calibration.prior_lower_,
        prior_upper=calibration.prior_upper_,
        n_training=calibration.n_training,
        degree=calibration.emulator_degree,
        walkers=walker_count(calibration.n_walkers, calibration.n_dim_),
        stage_steps=calibration.stage_steps,
        max_stages=calibration.max_stages,
        error_floor=calibration.model_error_range[0],
        discrepancy=(
            (
                DiscrepancyBasis.of_campaign(operating["pinion_speed"], operating["drive_torque"]),
                tau_grid(calibration.discrepancy_range),
            )
            if calibration.discrepancy
            else None
        ),
    )
    return model, work
