"""Pitch-error correction of the observed mesh harmonics.

Every manufactured gear has random single-pitch errors (ISO 1328-1 grades 6
to 8 on traction gears). They put shaft-order sidebands around each mesh
harmonic, and they also change the mesh harmonics themselves, systematically
and not by a little: on the reference locomotive gear, class-7 errors move
the second harmonic at 3800 rpm by -17 to -22 % (two draws), at 800 rpm by
+8 to +10 %, while most harmonics move by under 1 %. The change is not linear
in the error level (it grew with the level to the power 1.8 to 3.3 between
half and 1.4 times class 7) and depends strongly on where the operating point
sits against the resonances (at stiffness 1.00 and damping 0.06 instead of
0.98 and 0.044 the same draw moved that harmonic by +140 %). A model without
pitch errors fitted to such data moves its stiffness and damping to mimic
them: the truth fell outside the 90 % intervals by 1-2 % (mesh damping high,
stiffness low) on half the class-7 campaigns.

The model of the calibration stays mesh-periodic (that is what makes it fast),
so the pitch errors enter as a correction of the observed features, computed
where the posterior already is:

1. whether: at least :data:`MIN_VISIBLE_FRACTION` of the rig's first
   shaft-order sidebands (orders 1 to 3 of each shaft on each side of each
   harmonic, read with the features) stand :data:`MIN_SIDEBAND_SNR` noise
   std above its noise; a gear without pitch errors shows 2-3 %, and nothing
   is simulated for it;
2. the level the sidebands read as, from orders 1 to :data:`SIDEBAND_ORDERS`:
   the rig's (noise power removed) against
   the model's at the current posterior medians with one class-7 draw, as
   the mean over the sideband orders of each order's median log power ratio
   (a ratio of two random draws' line powers has median 1, so a median is not
   thrown by a few lines of other origin, e.g. a run-out's first sidebands),
   with the spread of those medians as its uncertainty. It is reported; as an
   estimate it scattered by a factor 0.6 to 1.7 around the truth on class 6
   to 8 virtual-rig gears, so the correction uses the stated classes
   (``classes``, default 6 to 8) and this level only when none are stated;
   a level below :data:`MIN_SCALE` (finer than about class 3) is not applied;
3. the change: ``draws`` random class-7 draws scaled to levels spread evenly
   over the stated classes (or over the read level's uncertainty), each
   simulated with the virtual rig's model at the posterior medians and read
   with the same line fit as the rig; the mean change of each log harmonic
   amplitude is taken off the observed one, and the spread between the draws
   (the rig's own draw is unknown) is added to that feature's variance.
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
import scipy.stats
import xarray as xr

from ..physics.design import Design
from ..physics.effects import Effect
from ..physics.pitch_errors import (
    DEFAULT_CLASSES,
    REFERENCE_CLASS,
    PitchErrors,
    class_level,
    draw_at_level,
    draw_pitch_errors,
)
from ..rig.features import extract_features, sampling_rate
from ..rig.virtual_rig import simulate_campaign
from .harmonics import HARMONIC_CHANNELS, harmonic_lines, observed_harmonics
from .likelihood import OPERATING_VARIABLES, Features

#: Levels below this fraction of class 7 (about ISO class 3) are not applied.
MIN_SCALE = 0.25
#: A sideband counts where the reference draw raises its power this many noise std above the rig's noise.
MIN_SIDEBAND_SNR = 3.0
#: Shaft orders on each side of a mesh harmonic whose sidebands give the level.
SIDEBAND_ORDERS = 10
#: Fewest such sidebands for a level to be read.
MIN_SIDEBANDS = 12
#: Fewest of the rig's sidebands, as a fraction, that must stand out before a level is looked for (a healthy,
#: error-free gear's records show 2-3 % at 3 noise std: the model's own sidebands at low speed and chance).
MIN_VISIBLE_FRACTION = 0.1
#: Run-in of the correction's simulations, s: the transients of the model decay within a few hundredths.
RUN_IN = 0.25


@dataclass(frozen=True)
class PitchCorrection:
    """The pitch-error correction of a campaign's mesh-harmonic features.

    ``shift`` and ``variance`` are over (op, channel, harmonic) like the
    features: the expected change of the log amplitude and its variance
    between draws; zero where not applied.
    """

    applied: bool
    reason: str
    scale: float | None
    log_sd: float
    classes: tuple[float, float] | None
    sidebands_used: int
    draws: int
    shift: np.ndarray
    variance: np.ndarray
    seconds: float

    @property
    def equivalent_class(self) -> float | None:
        """The ISO 1328-1 class whose tolerance is ``scale`` times class 7's (tolerances grow by sqrt 2 a class)."""
        if self.scale is None or not self.scale > 0:
            return None
        return REFERENCE_CLASS + 2.0 * math.log2(self.scale)

    def apply(self, features: Features) -> Features:
        """The features with the correction: log amplitudes shifted, the draws' spread added to their variance."""
        if not self.applied:
            return features
        used = features.used
        return replace(
            features,
            log_observed=np.where(used, features.log_observed - self.shift, 0.0),
            noise_variance=np.where(used, features.noise_variance + self.variance, 1.0),
        )

    def summary(self, used: np.ndarray) -> dict[str, Any]:
        """JSON-ready record (``pitch_errors`` of ``calibration.json``)."""
        shift = np.abs(self.shift[used]) if self.applied else np.zeros(0)
        spread = np.sqrt(self.variance[used]) if self.applied else np.zeros(0)
        return {
            "applied": self.applied,
            "reason": self.reason,
            "classes": None if self.classes is None else list(self.classes),
            "scale_to_class_7": self.scale,
            "scale_log_sd": self.log_sd if math.isfinite(self.log_sd) else None,
            "equivalent_iso1328_class": self.equivalent_class,
            "sidebands_used": self.sidebands_used,
            "draws": self.draws,
            "max_abs_log_shift": float(shift.max()) if shift.size else 0.0,
            "median_abs_log_shift": float(np.median(shift)) if shift.size else 0.0,
            "max_draw_spread": float(spread.max()) if spread.size else 0.0,
            "seconds": self.seconds,
            "method": "rig sidebands vs the model's with ISO 1328-1 class-7 draws at the posterior medians "
            "give the level; the mean change of the log mesh harmonics over scaled draws is "
            "taken off the observed ones, their spread added to the variance",
        }


def sideband_amplitudes(
    rig: xr.Dataset, design: Design, *, channels: Sequence[str] = HARMONIC_CHANNELS, n_harmonics: int = 3
) -> xr.Dataset:
    """:func:`~.harmonics.observed_harmonics` with the sidebands of shaft orders j = 1..:data:`SIDEBAND_ORDERS`.

    Far enough out to see the tooth-to-tooth part of the pitch errors (white
    over the orders), not only the few low orders of their running sum.
    """
    present = [name for name in channels if name in rig.data_vars]
    features = extract_features(
        rig,
        design,
        channels=present,
        n_harmonics=n_harmonics,
        n_sidebands=min(SIDEBAND_ORDERS, (design.z1 - 1) // 2),
        n_shaft_orders=0,
        n_motor_lines=0,
    )
    return harmonic_lines(features, rig.sizes["time"], n_harmonics)


def _channels_and_noise(observed: xr.Dataset, channels: Sequence[str]) -> tuple[np.ndarray, np.ndarray]:
    """Which channels count, and each line's noise std, both broadcast over (op, channel, harmonic, sideband)."""
    channel_used = np.array([name in channels for name in HARMONIC_CHANNELS])[None, :, None, None]
    return channel_used, observed["amplitude_std"].values[..., None]


def _visible_sidebands(observed: xr.Dataset, channels: Sequence[str]) -> tuple[int, int]:
    """How many of the rig's sidebands stand :data:`MIN_SIDEBAND_SNR` noise std above its noise, of how many."""
    channel_used, noise = _channels_and_noise(observed, channels)
    amplitude = observed["sideband_amplitude"].values
    with np.errstate(invalid="ignore"):
        visible = int(np.sum(channel_used & (amplitude >= MIN_SIDEBAND_SNR * noise)))
    return visible, int(np.sum(channel_used & np.isfinite(amplitude) & np.isfinite(noise)))


def _sideband_level(
    observed: xr.Dataset, clean: xr.Dataset, reference: xr.Dataset, channels: Sequence[str]
) -> tuple[float | None, float, int]:
    """Scale of the rig's pitch errors relative to the reference draw, the standard deviation of its log, and how
    many sidebands were used.

    The sidebands of one shaft order j (all harmonics, channels and runs) come
    from the same few components of the two gears' pitch-error spectra, so they
    are not independent: the level is the mean over the orders (pinion and
    gear, each order and side) of each order's median log power ratio, and its
    uncertainty the spread of those medians over the square root of their count.
    """
    channel_used, noise = _channels_and_noise(observed, channels)
    rig_power = observed["sideband_amplitude"].values ** 2 - noise**2
    model_power = clean["sideband_amplitude"].values ** 2
    raised = reference["sideband_amplitude"].values ** 2 - model_power
    with np.errstate(invalid="ignore"):
        usable = (
            channel_used
            & np.isfinite(rig_power)
            & np.isfinite(raised)
            & np.isfinite(model_power)
            & (raised >= (MIN_SIDEBAND_SNR * noise) ** 2)
        )
    count = int(usable.sum())
    if count < MIN_SIDEBANDS:
        return None, math.inf, count
    # a sideband below the noise counts as a small power, not as none: its log stays finite
    excess = np.maximum(rig_power - model_power, (0.1 * noise) ** 2)
    with np.errstate(divide="ignore", invalid="ignore"):
        log_ratio = np.log(excess / raised)
    order_medians = [
        float(np.median(log_ratio[..., j][usable[..., j]])) for j in range(log_ratio.shape[-1]) if usable[..., j].any()
    ]
    level = float(np.mean(order_medians))
    spread = (
        float(np.std(order_medians, ddof=1) / math.sqrt(len(order_medians))) if len(order_medians) > 1 else math.inf
    )
    # power ratios to amplitude scale
    return math.exp(0.5 * level), 0.5 * spread, count


def pitch_error_correction(
    rig: xr.Dataset,
    design: Design,
    features: Features,
    point: Mapping[str, float],
    adhesion_torque: Sequence[float],
    *,
    seed: np.random.SeedSequence,
    effects: Sequence[Effect] = (),
    channels: Sequence[str] = HARMONIC_CHANNELS,
    n_harmonics: int = 3,
    draws: int = 4,
    classes: tuple[float, float] | None = DEFAULT_CLASSES,
) -> PitchCorrection:
    """The pitch-error correction of ``features`` (module docstring).

    Parameters
    ----------
    rig : xarray.Dataset
        The campaign, order-tracked (constant speed per record).
    design : Design
        The nominal design.
    features : Features
        The campaign's features (:func:`~.likelihood.observed_features`).
    point : mapping
        Current estimate of the global parameters (``mesh_stiffness_scale``, design keys).
    adhesion_torque : sequence of float
        Current estimate of each run's T2, N m.
    seed : SeedSequence
        Source of the draws and of the simulated records' starts.
    effects : sequence of Effect
        The model's fixed effects.
    channels, n_harmonics :
        As for the features.
    draws : int
        Scaled class-7 draws averaged.
    classes : (float, float) or None
        ISO 1328-1 flank tolerance classes the rig's gears are made to (the
        drawing's grade; ``(7, 7)`` when known exactly): the draws' levels
        are spread evenly over them. None: the level read from the sidebands,
        spread over its uncertainty (an estimate from one campaign's
        sidebands, measured to scatter by a factor 0.6-1.7 around the truth on
        class 6-8 virtual-rig gears). Either way the level the sidebands show
        is reported, and nothing is corrected where they show none.
    """
    started = time.perf_counter()
    fs = sampling_rate(rig["time"].values, where="rig data: time")
    shape = features.used.shape
    record_seed, draw_seed = seed.spawn(2)
    draw_rng = np.random.default_rng(draw_seed)
    model = _ModelCampaign(
        design=design,
        operating=rig[[name for name in OPERATING_VARIABLES if name in rig]],
        true_parameters={
            **{name: float(value) for name, value in point.items()},
            "adhesion_torque": [float(value) for value in adhesion_torque],
        },
        effects=effects,
        fs=fs,
        duration=rig.sizes["time"] / fs,
        record_seed=record_seed,
        simulated_channels=[name for name in HARMONIC_CHANNELS if name in rig.data_vars],
        channels=channels,
        n_harmonics=n_harmonics,
    )
    # the gate reads the first sidebands the features already hold: a gear without errors costs nothing
    visible, total = _visible_sidebands(features.observed, channels)
    needed = max(MIN_SIDEBANDS, math.ceil(MIN_VISIBLE_FRACTION * total))
    if visible < needed:
        # nothing to read a level from, and no simulation spent on finding that out
        return _not_applied(
            f"{visible} of {total} sidebands stand {MIN_SIDEBAND_SNR:g} noise std above the rig's "
            f"noise (at least {needed} needed): no pitch-error level to correct for, or one this "
            "rig's noise hides",
            None, math.inf, visible, classes, shape, started,
        )
    observed = sideband_amplitudes(rig, design, channels=channels, n_harmonics=n_harmonics)
    clean = model.simulate(None)
    reference = model.simulate(draw_pitch_errors(design, REFERENCE_CLASS, draw_rng))
    scale, log_sd, count = _sideband_level(observed, model.sidebands(clean), model.sidebands(reference), channels)
    if scale is None:
        return _not_applied(
            f"only {count} sidebands of a class-{REFERENCE_CLASS} gear would stand out of this "
            f"rig's noise (at least {MIN_SIDEBANDS} needed): the pitch-error level cannot be read, "
            "and no correction is made",
            None, log_sd, count, classes, shape, started,
        )
    if scale < MIN_SCALE:
        return _not_applied(
            f"sidebands at {scale:.2f} of class-{REFERENCE_CLASS} pitch errors (below "
            f"{MIN_SCALE}): their change of the mesh harmonics is below the model-error floor",
            scale, log_sd, count, classes, shape, started,
        )
    shift, variance = _harmonic_changes(model, clean, scale, log_sd, classes, draws, draw_rng)
    read = (
        f"the sidebands read as {scale:.2f} (x/ {math.exp(log_sd):.2f}) of class-{REFERENCE_CLASS} pitch "
        f"errors, about class {REFERENCE_CLASS + 2.0 * math.log2(scale):.1f} ({count} sidebands)"
    )
    reason = read if classes is None else f"ISO 1328-1 classes {classes[0]:g} to {classes[1]:g} as stated; {read}"

    return PitchCorrection(
        applied=True,
        reason=reason,
        scale=scale,
        log_sd=log_sd,
        classes=classes,
        sidebands_used=count,
        draws=draws,
        shift=shift,
        variance=variance,
        seconds=time.perf_counter() - started,
    )


@dataclass(frozen=True)
class _ModelCampaign:
    """The model's noise-free campaign at the current estimate, and the harmonics and sidebands read from it."""

    design: Design
    operating: xr.Dataset
    true_parameters: dict[str, Any]
    effects: Sequence[Effect]
    fs: float
    duration: float
    record_seed: np.random.SeedSequence
    simulated_channels: list[str]
    channels: Sequence[str]
    n_harmonics: int

    def simulate(self, pitch_errors: PitchErrors | None) -> xr.Dataset:
        """The campaign with ``pitch_errors`` (None: perfect gears)."""
        # the same record seed for every simulation: the same record starts, so differences are the pitch errors'
        return simulate_campaign(
            self.design,
            self.operating,
            true_parameters=self.true_parameters,
            effects=self.effects,
            relative_noise=0.0,
            fs=self.fs,
            duration=self.duration,
            run_in=RUN_IN,
            seed=np.random.SeedSequence(self.record_seed.entropy, spawn_key=self.record_seed.spawn_key),
            channels=self.simulated_channels,
            pitch_errors=pitch_errors,
        )

    def harmonics(self, campaign: xr.Dataset) -> xr.Dataset:
        """The mesh harmonics of a simulated campaign."""
        return observed_harmonics(campaign, self.design, channels=self.channels, n_harmonics=self.n_harmonics)

    def sidebands(self, campaign: xr.Dataset) -> xr.Dataset:
        """The sidebands of a simulated campaign."""
        return sideband_amplitudes(campaign, self.design, channels=self.channels, n_harmonics=self.n_harmonics)


def _not_applied(reason: str, scale: float | None, log_sd: float, count: int, classes: tuple[float, float] | None,
                 shape: tuple[int, ...], started: float) -> PitchCorrection:
    """No correction, and why."""
    return PitchCorrection(
        applied=False,
        reason=reason,
        scale=scale,
        log_sd=log_sd,
        classes=classes,
        sidebands_used=count,
        draws=0,
        shift=np.zeros(shape),
        variance=np.zeros(shape),
        seconds=time.perf_counter() - started,
    )


def _harmonic_changes(model: _ModelCampaign, clean: xr.Dataset, scale: float, log_sd: float,
                      classes: tuple[float, float] | None, draws: int,
                      draw_rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Mean and variance over the draws of the change of each log mesh harmonic that pitch errors make."""
    with np.errstate(divide="ignore", invalid="ignore"):
        base = np.log(model.harmonics(clean)["amplitude"].values)
        changes = []
        positions = (np.arange(draws) + 0.5) / draws
        if classes is None:
            # the level is uncertain too: the draws' levels sit at stratified quantiles of its log-normal estimate
            levels = scale * np.exp(min(log_sd, 1.0) * scipy.stats.norm.ppf(positions))
        else:
            # evenly over the stated classes; tolerances grow by sqrt(2) a class
            levels = class_level(classes, positions)
        for level in levels:
            scaled = model.harmonics(model.simulate(draw_at_level(model.design, level, draw_rng)))
            changes.append(np.log(scaled["amplitude"].values) - base)
    change = np.array(changes)
    finite = np.all(np.isfinite(change), axis=0)
    shift = np.where(finite, change.mean(axis=0), 0.0)
    variance = np.where(finite, change.var(axis=0, ddof=1) if draws > 1 else 0.0, 0.0)
    return shift, variance
