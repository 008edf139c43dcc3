"""The calibration's pitch-error correction: the level read from sidebands, the correction applied where used."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import xarray as xr

from uqgear.calibration.harmonics import HARMONIC_CHANNELS
from uqgear.calibration.likelihood import observed_features
from uqgear.calibration.pitch_correction import (
    PitchCorrection,
    _sideband_level,
    pitch_error_correction,
    sideband_amplitudes,
)
from uqgear.physics.design import load_design
from uqgear.rig.format import read_rig

DATA = Path(__file__).resolve().parent.parent / "data" / "rig"
LABELS = ["pinion+1", "pinion-1", "pinion+2", "pinion-2", "pinion+3", "pinion-3",
          "gear+1", "gear-1", "gear+2", "gear-2", "gear+3", "gear-3"]


def _harmonics(sideband: np.ndarray, noise: float) -> xr.Dataset:
    n_op, n_channel, n_harmonic, _ = sideband.shape
    return xr.Dataset({"amplitude": (("op", "channel", "harmonic"), np.ones((n_op, n_channel, n_harmonic))),
                       "amplitude_std": (("op", "channel", "harmonic"), np.full((n_op, n_channel, n_harmonic), noise)),
                       "sideband_amplitude": (("op", "channel", "harmonic", "sideband"), sideband)},
                      coords={"channel": list(HARMONIC_CHANNELS), "harmonic": np.arange(1, n_harmonic + 1),
                              "sideband": LABELS})


@pytest.mark.parametrize("scale", [0.5, 1.0, 1.6])
def test_the_level_is_read_from_the_sidebands_of_independent_draws(scale):
    """Rig and reference sidebands from independent random draws (Rayleigh amplitudes of equal mean power per
    order), the rig's scaled: the level comes back within its own stated uncertainty (3 sigma), and that
    uncertainty is a real one (not zero, below a factor 2)."""
    rng = np.random.default_rng(np.random.SeedSequence(11))
    shape = (8, 3, 3, len(LABELS))
    # each order's power is common to all harmonics, channels and runs (the same few pitch-error components)
    order_power = rng.exponential(1.0, (2, len(LABELS)))
    spread = rng.exponential(1.0, (2, *shape))
    reference = np.sqrt(order_power[0] * spread[0])
    rig_clean = scale * np.sqrt(order_power[1] * spread[1])
    noise = 1e-3
    rig = np.sqrt(rig_clean ** 2 + noise ** 2)          # the noise power the level removes again
    level, log_sd, count = _sideband_level(_harmonics(rig, noise), _harmonics(np.zeros(shape), noise),
                                           _harmonics(reference, noise), HARMONIC_CHANNELS)
    assert count == rig.size
    assert 0.0 < log_sd < math.log(2.0)
    assert abs(math.log(level / scale)) <= 3.0 * log_sd


def test_no_level_without_sidebands_above_the_noise():
    shape = (4, 3, 3, len(LABELS))
    quiet = np.full(shape, 1e-3)
    level, log_sd, count = _sideband_level(_harmonics(quiet, 1e-3), _harmonics(np.zeros(shape), 1e-3),
                                           _harmonics(quiet, 1e-3), HARMONIC_CHANNELS)
    assert level is None and count == 0 and math.isinf(log_sd)


def test_the_correction_shifts_and_widens_only_the_used_features():
    design = load_design("locomotive")
    rig = read_rig(DATA / "healthy.nc")
    features = observed_features(rig, design, channels=HARMONIC_CHANNELS, n_harmonics=3, min_snr=5.0,
                                 model_error_range=(0.01, 0.5))
    shift = np.full(features.used.shape, 0.1)
    variance = np.full(features.used.shape, 0.04)
    correction = PitchCorrection(applied=True, reason="test", scale=1.0, log_sd=0.1, classes=(6.0, 8.0),
                                 sidebands_used=100, draws=4,
                                 shift=shift, variance=variance, seconds=0.0)
    corrected = correction.apply(features)
    used = features.used
    np.testing.assert_array_equal(corrected.log_observed[used], features.log_observed[used] - 0.1)
    np.testing.assert_array_equal(corrected.noise_variance[used], features.noise_variance[used] + 0.04)
    np.testing.assert_array_equal(corrected.log_observed[~used], 0.0)
    np.testing.assert_array_equal(corrected.noise_variance[~used], 1.0)
    # the features themselves are not changed (the uncorrected ones stay for the report)
    assert features.log_observed is not corrected.log_observed
    summary = correction.summary(used)
    assert summary["applied"] and summary["max_abs_log_shift"] == pytest.approx(0.1)
    assert summary["equivalent_iso1328_class"] == pytest.approx(7.0)
    assert PitchCorrection(**{**correction.__dict__, "applied": False}).apply(features) is features


def test_a_gear_without_pitch_errors_gets_no_correction():
    """The public healthy campaign (no pitch errors): its sidebands are at the noise, nothing is simulated."""
    design = load_design("locomotive")
    rig = read_rig(DATA / "healthy.nc")
    features = observed_features(rig, design, channels=HARMONIC_CHANNELS, n_harmonics=3, min_snr=5.0,
                                 model_error_range=(0.01, 0.5))
    correction = pitch_error_correction(rig, design, features, {"mesh_stiffness_scale": 1.0},
                                        rig["adhesion_torque_lower"].values, seed=np.random.SeedSequence(0))
    assert not correction.applied
    assert "noise" in correction.reason and correction.seconds < 5.0
    assert not correction.shift.any() and not correction.variance.any()
    # ten shaft orders a side of each shaft, for each harmonic and channel
    sidebands = sideband_amplitudes(rig, design)["sideband_amplitude"]
    assert sidebands.sizes["sideband"] == 40 and sidebands.sizes["op"] == rig.sizes["op"]
