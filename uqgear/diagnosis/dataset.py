"""What a diagnosis hands back as data: the Dataset of ``diagnosis.nc`` (gap maps, scores, held-out spectra)."""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from typing import Any

import numpy as np
import scipy.signal
import xarray as xr

from ..rig.features import FEATURE_FAMILIES
from .allowances.interference import amplitude_spectrum
from .case import RigCase
from .decision import Decision
from .execution import simulate_task
from .gap_maps import line_signal_to_noise
from .result import DiagnosisResult
from .scoring import GAP_METRIC, GAP_NOISE_LEVEL, CandidateScore, capped_squares


def held_spectra(result: DiagnosisResult, ops: Sequence[int]) -> xr.Dataset:
    """Amplitude spectra of the rig and of the held-out predictions (nominal, model with the effects) for some runs.

    The model with the effects is the one with every named effect, or the
    best candidate when none is named.
    """
    case = result.case
    best = result.final if result.final is not None else result.best
    sources = ["rig", "nominal"] + (["with_effect"] if best is not None else [])
    taper = scipy.signal.get_window("hann", case.size)
    frequency = np.fft.rfftfreq(case.size, 1.0 / case.fs)
    top = min(case.processors[0].limit, 3.6 * case.design.z1 * float(case.speeds[list(ops)].max()) / 60.0)
    keep = frequency <= top
    values = np.full((len(ops), len(sources), len(case.channels), int(keep.sum())), np.nan)

    def spectrum(record: np.ndarray) -> np.ndarray:
        return amplitude_spectrum(record, taper)[keep]

    for i, op in enumerate(ops):
        for c, channel in enumerate(case.channels):
            if case.usable[op, c]:
                values[i, 0, c] = spectrum(case.rig[channel].values[op])
        fits = [(1, result.nominal.problem, result.nominal_held.vectors[op])]
        if best is not None:
            fits.append((2, best.fit.problem, best.held.vectors[op]))
        for source, problem, vector in fits:
            run = simulate_task(case, problem.run_task(vector, op))
            for c, channel in enumerate(case.channels):
                values[i, source, c] = spectrum(run.records[channel])
    # mean amplitude of the rig's white noise in a bin: s sqrt(pi/2), s its per-quadrature spread
    floor = case.noise_std[list(ops)] * math.sqrt(2.0 * np.sum(taper**2)) / taper.sum() * math.sqrt(math.pi / 2.0)
    return xr.Dataset(
        {
            "amplitude_spectrum": (
                ("spectrum_op", "source", "channel", "frequency"),
                values,
                {
                    "long_name": "amplitude spectrum (Hann window), held-out prediction for the models",
                    "units": "channel units",
                },
            ),
            "spectrum_noise_floor": (
                ("spectrum_op", "channel"),
                floor,
                {"long_name": "mean amplitude of the rig's white noise in one bin", "units": "channel units"},
            ),
        },
        coords={
            "spectrum_op": ("spectrum_op", np.asarray(ops, dtype=int), {"long_name": "run index"}),
            "source": ("source", sources),
            "channel": ("channel", list(case.channels)),
            "frequency": ("frequency", frequency[keep], {"units": "Hz"}),
        },
    )


def _family_map(z: np.ndarray, case: RigCase) -> np.ndarray:
    """Excess RMS (capped) standardised discrepancy per run, channel and feature family."""
    families = np.array(case.layout.families)
    out = np.full((case.n_op, len(case.channels), len(FEATURE_FAMILIES)), np.nan)
    for k, family in enumerate(FEATURE_FAMILIES):
        chosen = families == family
        if not chosen.any():
            continue
        squares = capped_squares(z[:, :, chosen])
        # a family without a compared feature in a run (short records merge its lines) is NaN, silently
        finite = np.isfinite(squares)
        count = finite.sum(axis=-1)
        mean = np.where(count > 0, np.where(finite, squares, 0.0).sum(axis=-1) / np.maximum(count, 1), np.nan)
        out[:, :, k] = np.sqrt(np.maximum(mean - GAP_NOISE_LEVEL, 0.0))
    return out


def result_dataset(result: DiagnosisResult, spectra: xr.Dataset | None = None) -> xr.Dataset:
    """The gap maps and scores as a Dataset (written to ``diagnosis.nc``)."""
    case = result.case
    data = {**_gap_variables(result), **_score_variables(result.scores), **_selection_variables(result)}
    coords = _coordinates(case, result.scores)
    coords["selected_effect"] = (
        "selected_effect",
        [chosen.entry.label for chosen in result.selected],
        {"long_name": "effects named, in the order forward selection added them"},
    )
    ds = xr.Dataset(data, coords=coords)
    if spectra is not None:
        ds = ds.merge(spectra)
    ds.attrs.update(
        title="uqgear sim-to-real gap diagnosis",
        verdict=result.verdict,
        reason=result.reason,
        gap_metric=GAP_METRIC,
        nominal_gap=result.nominal_gap,
        model_error=json.dumps(case.model_error),
        effects_considered=json.dumps(list(result.effects)),
        nominal_parameters=json.dumps(result.nominal.values),
        effects=json.dumps([chosen.entry.effect for chosen in result.selected]),
        remaining_gap=result.remaining_gap,
    )
    return ds


def _selection_variables(result: DiagnosisResult) -> dict[str, Any]:
    """The named effect set: each effect's shrink share and the gap after it; the final model's gap map.

    The final model's held-out discrepancies and gap map are written when
    it holds more than one effect (with one they are ``z_with_effect_heldout``
    and ``gap_map_with_effect``).
    """
    case = result.case
    selected = result.selected
    data: dict[str, Any] = {
        "shrink_share": (
            ("selected_effect",),
            [chosen.shrink_share for chosen in selected],
            {"long_name": "held-out gap shrink brought by the effect, fraction of the nominal gap", "units": "1"},
        ),
        "gap_after_effect": (
            ("selected_effect",),
            [chosen.entry.gap_with_effect for chosen in selected],
            {"long_name": "held-out gap with this and the earlier named effects", "units": "1"},
        ),
    }
    if len(selected) > 1:
        names = " + ".join(chosen.entry.label for chosen in selected)
        dims = ("op", "channel", "feature")
        held = selected[-1].entry.held
        data["final_heldout_model"] = (
            dims,
            held.model[..., case.layout.columns],
            {"long_name": f"model with {names}, run left out of the fit", "units": "channel units"},
        )
        data["z_final_heldout"] = (
            dims,
            held.z,
            {"long_name": f"standardised discrepancy on held-out runs, model with {names}", "units": "1"},
        )
        data["gap_map_final"] = (
            ("op", "channel", "family"),
            _family_map(held.z, case),
            {
                "long_name": f"excess RMS standardised discrepancy per feature family, held-out runs, with {names}",
                "units": "1",
            },
        )
    return data


def _noise_variables(case: RigCase) -> dict[str, Any]:
    """The white-noise levels the features are compared with: between the lines, and the low band's own."""
    return {
        "noise_std": (
            ("op", "channel"),
            case.noise_std,
            {"long_name": "white-noise level of the rig records (floor between the lines)", "units": "channel units"},
        ),
        "band_noise_std": (
            ("op", "channel"),
            case.band_noise_std,
            {"long_name": "white-noise level of the rig records' low band (its own floor)", "units": "channel units"},
        ),
    }


def _gap_variables(result: DiagnosisResult) -> dict[str, Any]:
    """Features, discrepancies and gap maps of the nominal model (and of the best effect) per run and channel."""
    case = result.case
    layout = case.layout
    best = result.best
    dims = ("op", "channel", "feature")
    data: dict[str, Any] = {
        "observed": (dims, case.observed, {"long_name": "rig features", "units": "channel units"}),
        "compared": (
            dims,
            case.mask().astype(np.int8),
            {
                "long_name": "feature enters the comparison: a usable run, a finite rig value, each spectral line "
                "once (1), else 0",
                "units": "1",
            },
        ),
        "nominal_model": (
            dims,
            result.nominal.model[..., layout.columns],
            {"long_name": "nominal model features (fitted to all runs)", "units": "channel units"},
        ),
        "nominal_heldout_model": (
            dims,
            result.nominal_held.model[..., layout.columns],
            {"long_name": "nominal model features, run left out of the fit", "units": "channel units"},
        ),
        "z_nominal": (dims, result.nominal.z, {"long_name": "standardised discrepancy, nominal fit", "units": "1"}),
        "z_nominal_heldout": (
            dims,
            result.nominal_held.z,
            {"long_name": "standardised discrepancy on held-out runs, nominal model", "units": "1"},
        ),
        "gap_map_nominal": (
            ("op", "channel", "family"),
            _family_map(result.nominal_held.z, case),
            {
                "long_name": "excess RMS standardised discrepancy (capped at 10) per feature family, "
                "held-out runs, nominal model",
                "units": "1",
            },
        ),
        **_noise_variables(case),
        "nominal_adhesion_torque": (
            ("op",),
            result.nominal.adhesion_torques,
            {"long_name": "adhesion torque T2 of the nominal fit", "units": "N m"},
        ),
        "nominal_periodic": (
            ("op",),
            result.nominal.periodic.astype(np.int8),
            {"long_name": "nominal model's steady response repeats (1) or not (0)", "units": "1"},
        ),
    }
    if best is not None:
        data["with_effect_heldout_model"] = (
            dims,
            best.held.model[..., layout.columns],
            {"long_name": f"model with {best.label}, run left out of the fit", "units": "channel units"},
        )
        data["z_with_effect_heldout"] = (
            dims,
            best.held.z,
            {"long_name": f"standardised discrepancy on held-out runs, model with {best.label}", "units": "1"},
        )
        data["gap_map_with_effect"] = (
            ("op", "channel", "family"),
            _family_map(best.held.z, case),
            {
                "long_name": "excess RMS standardised discrepancy per feature family, held-out runs, with "
                f"{best.label}",
                "units": "1",
            },
        )
    return data


def _score_variables(scores: Sequence[CandidateScore]) -> dict[str, Any]:
    """Held-out scores of the candidates, best first."""
    return {
        "score": (
            ("candidate",),
            [s.score for s in scores],
            {"long_name": "held-out log predictive density gain over nominal minus penalty", "units": "nat"},
        ),
        "delta_log_density": (
            ("candidate",),
            [s.delta_log_density for s in scores],
            {"long_name": "held-out log predictive density gain over nominal", "units": "nat"},
        ),
        "delta_log_density_se": (
            ("candidate",),
            [s.standard_error for s in scores],
            {"long_name": "standard error of the gain (over runs)", "units": "nat"},
        ),
        "gap_with_effect": (
            ("candidate",),
            [s.gap_with_effect for s in scores],
            {"long_name": "held-out gap with the effect", "units": "1"},
        ),
        "shrink_fraction": (
            ("candidate",),
            [s.shrink_fraction for s in scores],
            {"long_name": "1 - gap with effect / nominal gap, held-out runs", "units": "1"},
        ),
        "shrink_fraction_bounds": (
            ("candidate", "bound"),
            [list(s.shrink_interval) for s in scores],
            {"long_name": "5 % and 95 % bootstrap quantiles (runs resampled)", "units": "1"},
        ),
    }


def _coordinates(case: RigCase, scores: Sequence[CandidateScore]) -> dict[str, Any]:
    """Coordinates of :func:`result_dataset`: runs, channels, features, families, candidates."""
    layout = case.layout
    return {
        "op": ("op", np.arange(case.n_op)),
        "pinion_speed": ("op", case.speeds, {"units": "rpm"}),
        "drive_torque": ("op", case.drive_torques, {"units": "N m"}),
        "channel": ("channel", list(case.channels)),
        "feature": ("feature", list(layout.names)),
        "feature_family": ("feature", list(layout.families)),
        "feature_kind": ("feature", list(layout.kinds)),
        "family": ("family", list(FEATURE_FAMILIES)),
        "candidate": ("candidate", [s.label for s in scores]),
        "candidate_effect": ("candidate", [s.effect for s in scores]),
        "bound": ("bound", ["q05", "q95"]),
    }


def unfitted_dataset(case: RigCase, decision: Decision, effects: Sequence[str]) -> xr.Dataset:
    """The Dataset of ``diagnosis.nc`` where no model was fitted: the rig's features and their signal-to-noise.

    Data that cannot decide, or a differential diagnosis (which adds its
    change test); ``verdict`` and ``reason`` are the decision's.
    """
    layout = case.layout
    dims = ("op", "channel", "feature")
    data = {
        "observed": (dims, case.observed, {"long_name": "rig features", "units": "channel units"}),
        "line_snr": (
            dims,
            line_signal_to_noise(case),
            {"long_name": "line amplitude over its per-quadrature noise spread", "units": "1"},
        ),
        **_noise_variables(case),
    }
    coords = {
        "op": ("op", np.arange(case.n_op)),
        "pinion_speed": ("op", case.speeds, {"units": "rpm"}),
        "drive_torque": ("op", case.drive_torques, {"units": "N m"}),
        "channel": ("channel", list(case.channels)),
        "feature": ("feature", list(layout.names)),
        "feature_family": ("feature", list(layout.families)),
        "feature_kind": ("feature", list(layout.kinds)),
    }
    ds = xr.Dataset(data, coords=coords)
    ds.attrs.update(
        title="uqgear sim-to-real gap diagnosis",
        verdict=decision.verdict,
        reason=decision.reason,
        gap_metric=GAP_METRIC,
        model_error=json.dumps(case.model_error),
        effects_considered=json.dumps(list(effects)),
    )
    return ds


__all__ = ["held_spectra", "result_dataset", "unfitted_dataset"]
