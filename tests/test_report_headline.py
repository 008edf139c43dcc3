"""Every report answers first: the "What this shows" block, each statement checked against the data.

The checks below recompute every headline number from the result Datasets with plain numpy and
xarray (not with the report's own helpers), so a statement that is not true of the data fails.
"""

from __future__ import annotations

import json
import re

import numpy as np
import pytest
import xarray as xr

from uqgear.report.calibration_report import calibration_findings
from uqgear.report.diagnosis_report import diagnosis_findings
from uqgear.report.finding import headline_html
from uqgear.report.findings import separation_findings as section_separation
from uqgear.report.headline import (
    back_contact_findings,
    headline_findings,
    regime_findings_headline,
    separation_findings,
    worst_load_findings,
)
from uqgear.report.study_report import build_report, load_results

SPEED, T2 = "pinion_speed", "adhesion_torque"
PROVENANCE_IDS = ("summary", "summary-table", "design-table", "uncertain-table", "versions-table", "study-text")


# ---------------------------------------------------------------------------- independent recomputation


def _grids(results, name):
    """(analysis name, speeds, T2 values, values[speed, T2]) of every speed x T2 grid of ``name``."""
    found = []
    for ds in results:
        if name not in ds or SPEED not in ds[name].dims or set(ds[name].dims) - {SPEED, T2}:
            continue
        da = ds[name]
        if T2 in da.dims:
            da = da.sortby(SPEED).sortby(T2).transpose(SPEED, T2)
            t2 = da[T2].values.astype(float)
            values = da.values
        else:
            da = da.sortby(SPEED)
            constant = np.unique(ds[T2].values) if T2 in ds.coords else np.array([np.nan])
            t2 = constant.astype(float) if constant.size == 1 else np.array([np.nan])
            values = da.values[:, None]
        found.append((ds.attrs["analysis_name"], da[SPEED].values.astype(float), t2, values))
    return found


def _contiguous(speeds, mask):
    """[(first speed, last speed)] of each run of consecutive True values."""
    out, start = [], None
    for k, flag in enumerate(list(mask) + [False]):
        if flag and start is None:
            start = k
        elif not flag and start is not None:
            out.append((float(speeds[start]), float(speeds[k - 1])))
            start = None
    return out


def _worst(found):
    best = None
    for name, speeds, t2, values in found:
        values = values.astype(float)
        if not np.isfinite(values).any():
            continue
        i, j = np.unravel_index(np.nanargmax(values), values.shape)
        if best is None or values[i, j] > best[0]:
            best = (float(values[i, j]), name, float(speeds[i]), float(t2[j]))
    return best


def _check_worst_load(finding, results):
    name = "peak_mesh_force" if _grids(results, "peak_mesh_force") else "dynamic_load_factor"
    found = _grids(results, name)
    value, source, speed, t2 = _worst(found)
    facts = finding.facts
    assert facts["qoi"] == name
    assert facts["value"] == pytest.approx(value) and facts["speed"] == speed and facts["t2"] == pytest.approx(t2)
    assert facts["runs"] == sum(np.isfinite(values.astype(float)).sum() for _, _, _, values in found)
    assert f"{speed:.4g} rpm" in finding.text and f"T2 = {t2 / 1e3:.4g} kN m" in finding.text
    if name == "peak_mesh_force":
        assert f"peak mesh force {value / 1e3:.4g} kN" in finding.text
        factor, _, factor_speed, factor_t2 = _worst(_grids(results, "load_factor_rated"))
        assert facts["factor_rated"] == pytest.approx(factor)
        assert f"{factor:.3g} x the mesh force at rated torque" in finding.text or \
            f"{factor:.3g}, is at {factor_speed:.4g} rpm" in finding.text
    else:
        assert f"rated load) {value:.3g}" in finding.text and "run's own static mesh force" in finding.text


def _check_separation(finding, results):
    grids = _grids(results, "fraction_separation")
    chosen = max(grids, key=lambda g: (g[2].size >= 2, g[1].size, g[2].size))
    name, speeds, t2, values = chosen
    facts = finding.facts
    assert facts["source"] == name
    column = {"low": 0, "high": t2.size - 1, "only": 0}[facts["end"]]
    assert facts["t2"] == pytest.approx(t2[column])
    ds = next(ds for ds in results if ds.attrs["analysis_name"] == name)
    separation = ds["fraction_separation"].sel({T2: t2[column]}) if T2 in ds["fraction_separation"].dims \
        else ds["fraction_separation"]
    separation = separation.sortby(SPEED)
    ranges = _contiguous(separation[SPEED].values, separation.values > 0)
    assert [tuple(r) for r in facts["ranges"]] == ranges
    assert facts["max_fraction"] == pytest.approx(float(separation.max()))
    assert f"T2 = {t2[column] / 1e3:.4g} kN m" in finding.text
    for low, high in ranges:
        assert (f"between {low:.4g} and {high:.4g} rpm" if low != high else f"at {low:.4g} rpm") in finding.text
    if ranges:
        assert f"up to {100 * float(separation.max()):.3g} % of the time" in finding.text
    else:
        assert "stay in contact at every speed" in finding.text


def _check_back_contact(finding, results):
    found = _grids(results, "fraction_back_contact")
    value = max(float(np.nanmax(values)) for _, _, _, values in found)
    assert finding.facts["occurs"] == (value > 0) and finding.facts["max_fraction"] == pytest.approx(value)
    assert finding.facts["runs"] == sum(np.isfinite(values.astype(float)).sum() for _, _, _, values in found)
    if value > 0:
        assert f"up to {100 * value:.3g} % of the time" in finding.text
    else:
        assert finding.text.startswith("No back-side contact") and f"{finding.facts['runs']} runs" in finding.text


def _check_regimes(finding, results):
    grids = _grids(results, "regime")
    name, speeds, t2, labels = max(grids, key=lambda g: (g[2].size, g[1].size))
    labels = labels.astype(str)
    facts = finding.facts
    assert facts["source"] == name
    windows = []
    for j in range(t2.size):
        ranges = _contiguous(speeds, labels[:, j] != "period-1")
        if ranges:
            names = [sorted(set(labels[(speeds >= low) & (speeds <= high), j].tolist())) for low, high in ranges]
            windows.append((float(t2[j]), ranges, names))
    assert len(facts["windows"]) == len(windows)
    for window, (level, ranges, names) in zip(facts["windows"], windows):
        assert window["t2"] == pytest.approx(level)
        assert [tuple(r) for r in window["ranges"]] == ranges
        assert [sorted(n) for n in window["labels"]] == names
        assert f"T2 = {level / 1e3:.4g} kN m" in finding.text
    found = sorted({label for label in labels.ravel() if label != "period-1"})
    assert sorted(facts["labels"]) == found
    for label in found:
        # more than three period-n labels are listed as "period-n with n = 2, 4, ..."
        number = label.split("-", 1)[1] if label.startswith("period-") else None
        assert label in finding.text or re.search(rf"period-n with n = [0-9, ]*\b{number}\b", finding.text), label
    quiet = [float(v) for j, v in enumerate(t2) if (labels[:, j] == "period-1").all()]
    assert facts["period1_t2"] == pytest.approx(quiet)
    if not windows:
        assert finding.text.startswith("Period-1 (harmonic) response at all")


def _check_sobol(finding, results):
    ds = next(ds for ds in results if ds.attrs["analysis_name"] == finding.facts["source"])
    name = finding.facts["qoi"]
    totals = ds[name].sel(index="ST")
    half = ds[f"{name}_conf"].sel(index="ST")
    for point in finding.facts["points"]:
        at = {SPEED: point["speed"]} if SPEED in totals.dims else {}
        row, width = totals.sel(at).to_series(), half.sel(at).to_series()
        if point["top"] is None:
            assert row.isna().all()
            continue
        ranked = row.sort_values(ascending=False, kind="stable")
        assert point["top"] == ranked.index[0] and point["st"] == pytest.approx(ranked.iloc[0])
        assert point["runner_up"] == ranked.index[1] and point["runner_up_st"] == pytest.approx(ranked.iloc[1])
        top, second = ranked.index[0], ranked.index[1]
        assert point["resolved"] == bool(row[top] - width[top] > row[second] + width[second])
        assert f"{point['st']:.2f}" in finding.text
        if at:
            assert f"{point['speed']:.4g}" in finding.text


def _check_continuation(finding, results):
    """Separation onsets, folds and coexistence windows recomputed from the bifurcation table."""
    ds = next(ds for ds in results if ds.attrs.get("analysis_type") == "continuation")
    facts = finding.facts
    for case, entry in enumerate(facts["cases"]):
        kinds = ds["bifurcation_type"].values[case].astype(str)
        parameter = ds["bifurcation_parameter"].values[case]
        main = (ds["bifurcation_branch"].values[case] == 0) & (ds["bifurcation_period"].values[case] == 1)
        onsets = parameter[main & (kinds == "grazing_separation") & (ds["bifurcation_side"].values[case] > 0)]
        if onsets.size:
            assert entry["separation_onset"] == pytest.approx(onsets.min())
        else:
            assert np.isnan(entry["separation_onset"])
        folds = np.sort(parameter[main & (kinds == "fold")])
        assert [value for value, _ in entry["folds"]] == pytest.approx(list(folds))
        for window in entry["coexistence"]:
            assert window["low"] < window["high"]
            if f"{window['low']:.4g}" in finding.text:
                assert f"{window['forces'][0] / 1e3:.4g}" in finding.text
    if "begin to separate" in finding.text:
        shown = [e["separation_onset"] for e in facts["cases"] if np.isfinite(e["separation_onset"])]
        assert all(f"{value:.4g}" in finding.text for value in shown)


def _check_coexistence(finding, results):
    ds = next(ds for ds in results if ds.attrs.get("analysis_name") == finding.facts["source"])
    count = ds["attractor_count"].values
    assert finding.facts["points_with_several"] == int((count > 1).sum())
    assert finding.facts["most"] == int(count.max())


def _check_prediction(finding, results):
    """The worst case's band recomputed: where the median draw's upper bound is highest, its lowest and highest
    quantiles (and the prior's, or the note that the draws are the study's)."""
    ds = next(ds for ds in results if ds.attrs.get("analysis_type") == "prediction")
    facts = finding.facts
    if "extrapolated" in facts or "effects" in facts or "discrepancy" in facts:
        return
    upper = ds[facts["qoi"]].sel(bound="upper")
    median = upper.isel(quantile=int(np.argmin(np.abs(ds["quantile"].values - 0.5))))
    flat = int(np.argmax(median.values))
    at = {dim: int(index) for dim, index in zip(median.dims, np.unravel_index(flat, median.shape))}
    assert {dim: int(index) for dim, index in facts["at"].items()} == at
    band = upper.isel(at).values
    assert facts["posterior"] == pytest.approx([band[0], band[-1]])
    assert f"{band[0] / 1e3:.4g}-{band[-1] / 1e3:.4g} kN" in finding.text
    if f"{facts['qoi']}_prior" in ds:
        prior = ds[f"{facts['qoi']}_prior"].sel(bound="upper").isel(at).values
        assert facts["prior"] == pytest.approx([prior[0], prior[-1]])
    else:
        assert "draws of the study's distributions" in finding.text


def _check_rating(finding, results):
    facts = finding.facts
    ds = next(ds for ds in results if ds.attrs.get("analysis_type") == "rating")
    lower = ds[f"safety_factor_{facts['mode']}"].sel(bound="lower")
    assert facts["safety_factor"] == pytest.approx(float(lower.min()))
    at = lower.sel(gear=facts["gear"], pinion_speed=facts["pinion_speed"])
    assert float(at) == pytest.approx(facts["safety_factor"])
    assert facts["minimum"] == lower.attrs["minimum"]
    assert f"{facts['safety_factor']:.2f} ({facts['gear']}, {facts['pinion_speed']:.0f} rpm)" in finding.text
    iso = ds[f"safety_factor_{facts['mode']}_iso"].sel(gear=facts["gear"], pinion_speed=facts["pinion_speed"])
    assert facts["safety_factor_iso"] == pytest.approx(float(iso))
    assert facts["damage"] == pytest.approx(float(ds["damage"].sel(mode=facts["mode"]).max()))


def _check_runup(finding, results):
    facts = finding.facts
    ds = next(ds for ds in results if ds.attrs.get("analysis_type") == "runup")
    peaks = ds["peak_mesh_force_case"]
    if "peak_up" in facts or "peak_down" in facts:
        for direction in peaks["direction"].values:
            values = peaks.sel(direction=direction)
            assert facts[f"peak_{direction}"] == pytest.approx(float(values.max()))
            where = values.where(values == values.max(), drop=True)["pinion_speed"].values
            assert facts[f"speed_{direction}"] in where
            assert f"{facts[f'peak_{direction}'] / 1e3:.1f} kN at {facts[f'speed_{direction}']:.0f} rpm" in finding.text
    elif "hysteresis" in facts:
        up, down = (peaks.sel(direction=d).values for d in ("up", "down"))
        differ = (np.abs(up - down) > 0.1 * np.maximum(np.abs(up), np.abs(down))).any(axis=0)
        lower, upper = ds["bin_lower"].values, ds["bin_upper"].values
        expected = [(float(lower[k]), float(upper[k])) for k in np.flatnonzero(differ)]
        # consecutive bins merge into one range
        merged = []
        for low, high in expected:
            if merged and merged[-1][1] == low:
                merged[-1] = (merged[-1][0], high)
            else:
                merged.append((low, high))
        assert [tuple(r) for r in facts["hysteresis"]] == merged
    else:
        for direction in ds["direction"].values:
            speeds = ds["jump_speed"].sel(direction=direction).values
            assert facts[f"jumps_{direction}"] == sorted(set(speeds[np.isfinite(speeds)].tolist()))


CHECKS = {"rating": _check_rating, "runup": _check_runup, "worst_load": _check_worst_load,
          "separation": _check_separation, "back_contact": _check_back_contact,
          "regimes": _check_regimes, "sobol": _check_sobol, "continuation": _check_continuation,
          "coexistence": _check_coexistence, "prediction": _check_prediction}


def check_every_finding(results) -> list[str]:
    """Check each headline finding against the data; the topics checked."""
    findings = headline_findings(results)
    assert findings
    for finding in findings:
        assert finding.topic in CHECKS, finding
        CHECKS[finding.topic](finding, results)
    return [finding.topic for finding in findings]


def _body(text: str) -> str:
    return text[text.index("<body>") + len("<body>"):]


def check_page_order(text: str) -> None:
    body = _body(text)
    assert body.lstrip().startswith("<h1>")
    after_title = body[body.index("</h1>") + len("</h1>"):].lstrip()
    assert after_title.startswith('<section id="what-this-shows"><h2>What this shows</h2>')
    headline = body.index('id="what-this-shows"')
    opening = body.index('<details id="provenance"><summary>Provenance: study, design, parameters, versions, '
                         'seeds</summary>')
    closing = body.rindex("</details>")
    assert headline < body.index('id="findings"') < body.index('class="analysis"') < opening
    assert "<table" not in body[:headline]
    for identifier in PROVENANCE_IDS:
        if identifier in ("uncertain-table", "study-text") and f'id="{identifier}"' not in body:
            continue        # results without uncertain parameters or study text (synthetic ones)
        position = body.index(f'id="{identifier}"')
        assert opening < position < closing, identifier
    assert body[closing:].replace("\n", "") == "</details></body></html>"


# ---------------------------------------------------------------------------- the smoke study


@pytest.fixture(scope="module")
def smoke(smoke_study_run):
    """The smoke study's results and report, from its run through the command line (tests/conftest.py)."""
    completed, folder = smoke_study_run
    assert completed.returncode == 0, completed.stderr
    return load_results(folder), (folder / "report.html").read_text()


def test_report_opens_with_what_this_shows_and_ends_with_collapsed_provenance(smoke):
    results, text = smoke
    check_page_order(text)
    for finding in headline_findings(results):
        assert headline_html([finding]).split("<li>")[1].split("</li>")[0] in text


def test_every_smoke_headline_finding_is_true_of_the_netcdf_data(smoke):
    results, _ = smoke
    topics = check_every_finding(results)
    # the smoke results have every kind of grid statement and a Sobol analysis of three QoIs
    # the rating's verdict comes first (one line per failure mode), then a prediction (the band of the
    # worst case), then the grid statements
    assert topics[:8] == ["rating", "rating", "prediction", "worst_load", "separation", "separation",
                          "back_contact", "regimes"]
    # guided starts (the default) add what they found about coexisting responses, the continuation and the
    # run-up theirs
    assert topics[-3:] == ["sobol", "sobol", "sobol"]
    assert set(topics[8:-3]) == {"coexistence", "continuation", "runup"}


# ---------------------------------------------------------------------------- synthetic grids

INTERVAL = (21.0e3, 46.0e3)


def _grid_dataset(**variables) -> xr.Dataset:
    speeds = np.arange(1000.0, 6001.0, 100.0)
    t2 = np.array([INTERVAL[0], 30.0e3, 38.0e3, INTERVAL[1]])
    ds = xr.Dataset({name: ((SPEED, T2), values) for name, values in variables.items()},
                    coords={SPEED: speeds, T2: t2})
    ds.attrs.update(analysis_name="regime_map", analysis_type="regime_map", analysis_index=0,
                    axes=json.dumps([SPEED, T2]), study_name="synthetic",
                    uncertain_parameters=json.dumps({T2: {
                        "kind": "interval", "lower": INTERVAL[0], "upper": INTERVAL[1],
                        "source": "T2 = mu Q R_w: mu in [0.15, 0.33]"}}))
    return ds


def _separation_grid() -> tuple[np.ndarray, np.ndarray]:
    speeds = np.arange(1000.0, 6001.0, 100.0)
    fraction = np.zeros((speeds.size, 4))
    fraction[speeds >= 3700, 0] = 0.3                                   # wet rail: wide, up to the top
    fraction[(speeds >= 4000) & (speeds <= 5500), 1] = 0.25
    fraction[(speeds >= 4200) & (speeds <= 5000), 2] = 0.22
    fraction[(speeds >= 4300) & (speeds <= 4800), 3] = 0.2             # dry rail: high speeds only
    fraction[speeds == 4500, 3] = 0.23
    return speeds, fraction


def test_separation_is_stated_for_each_end_of_the_t2_interval():
    speeds, fraction = _separation_grid()
    ds = _grid_dataset(fraction_separation=fraction)
    wet, dry = separation_findings([ds])
    assert wet.text == ("Wet rail (T2 = 21 kN m, low end of its interval): teeth separate between 3700 and "
                        "6000 rpm (the top of the sweep), up to 30 % of the time (at 3700 rpm); regime_map runs, "
                        "every 100 rpm.")
    assert dry.text == ("Dry rail (T2 = 46 kN m, high end of its interval): teeth separate between 4300 and "
                        "4800 rpm, up to 23 % of the time (at 4500 rpm); regime_map runs, every 100 rpm.")
    assert wet.facts["ranges"] == [(3700.0, 6000.0)] and dry.facts["ranges"] == [(4300.0, 4800.0)]
    check_every_finding([ds])
    # the regime map section says the same, per end, never "for all T2"
    sentences = section_separation(ds["fraction_separation"], SPEED, T2)
    assert sentences[:2] == ["teeth separate (contact loss) between 3700 and 6000 rpm at T2 = 21 kN m, up to 30 % "
                             "of the time",
                             "teeth separate (contact loss) between 4300 and 4800 rpm at T2 = 46 kN m, up to 23 % "
                             "of the time"]
    assert sentences[2] == ("teeth separate (contact loss) at the 2 T2 values in between too: all of it between "
                            "4000 and 5500 rpm, up to 25 % of the time")


def test_the_regime_map_section_in_the_report_states_separation_per_end():
    speeds, fraction = _separation_grid()
    labels = np.full(fraction.shape, "period-1", dtype="<U40")
    ds = _grid_dataset(fraction_separation=fraction, regime=labels)
    text = build_report([ds], dpi=40)
    section = text[text.index('id="analysis-regime_map"'):]
    assert "teeth separate (contact loss) between 4300 and 4800 rpm at T2 = 46 kN m" in section
    assert "between 3700 and 6000 rpm at T2 = 21 kN m" in section
    assert "for all T2" not in text
    check_page_order(text)


def test_regime_windows_name_every_label_other_than_period_1():
    speeds = np.arange(1000.0, 6001.0, 100.0)
    labels = np.full((speeds.size, 4), "period-1", dtype="<U40")
    labels[(speeds >= 3800) & (speeds <= 3900), 0] = "period-5"
    labels[(speeds >= 4000) & (speeds <= 4100), 0] = "uncertain"
    labels[speeds == 4200, 0] = "quasi_periodic_or_long_period"
    labels[speeds == 5000, 1] = "chaotic"
    ds = _grid_dataset(regime=labels)
    [finding] = regime_findings_headline([ds])
    assert finding.text == (
        "Response not period-1 (labels found: period-5, uncertain, quasi_periodic_or_long_period, chaotic): at "
        "T2 = 21 kN m (wet rail) between 3800 and 4200 rpm (period-5, uncertain, quasi_periodic_or_long_period); "
        "at T2 = 30 kN m at 5000 rpm (chaotic); period-1 at every speed when T2 >= 38 kN m "
        "(regime_map, speed 1000-6000 rpm).")
    check_every_finding([ds])


def test_worst_load_uses_peak_mesh_force_when_present_and_the_load_factor_otherwise():
    speeds = np.arange(1000.0, 6001.0, 100.0)
    factor = np.ones((speeds.size, 4))
    factor[speeds == 3900, 0] = 3.5
    force = factor * np.array([60e3, 70e3, 80e3, 90e3])
    without = _grid_dataset(dynamic_load_factor=factor, fraction_back_contact=np.zeros_like(factor))
    [load] = worst_load_findings([without])
    assert load.text == ("Worst dynamic load factor (peak mesh force over the run's own static mesh force, not over "
                         "the rated load) 3.5 at 3900 rpm, T2 = 21 kN m (wet rail); largest of the 204 runs of "
                         "regime_map.")
    with_force = _grid_dataset(dynamic_load_factor=factor, peak_mesh_force=force, load_factor_rated=force / 60e3)
    [load] = worst_load_findings([with_force])
    assert load.text == ("Worst dynamic load: peak mesh force 210 kN at 3900 rpm, T2 = 21 kN m (wet rail), 3.5 x the "
                         "mesh force at rated torque; largest of the 204 runs of regime_map.")
    [back] = back_contact_findings([without])
    assert back.text == ("No back-side contact (impact on the rear flanks) in any of the 204 runs of regime_map "
                         "(speed 1000-6000 rpm, T2 21-46 kN m).")
    for results in ([without], [with_force]):
        check_every_finding(results)


# ---------------------------------------------------------------------------- calibration and diagnosis


def _calibration_content(converged: bool = True) -> dict:
    parameters = {
        "mesh_stiffness_scale": {"q05": 0.965, "q50": 0.969, "q95": 0.973, "prior": [0.7, 1.3], "units": "1"},
        "backlash": {"q05": 0.22e-3, "q50": 0.295e-3, "q95": 0.376e-3, "prior": [0.21e-3, 0.39e-3], "units": "m"},
        "k1": {"q05": 1.008e9, "q50": 1.010e9, "q95": 1.012e9, "prior": [0.6e9, 1.5e9], "units": "N m-1"},
    }
    content = {"converged": converged,
               "diagnostics": {"reasons": [] if converged else ["split R-hat 1.271 > 1.01"], "tau_max": 46.4,
                               "rhat_max": 1.008, "ess_min": 8045.0},
               "predictive_check": {"fraction_within_2_sigma": 71 / 72, "features_used": 72, "max_abs_z": 2.32,
                                    "passed": True}}
    if converged:
        content["parameters"] = parameters
    else:
        content.update(parameters=None, unconverged_estimates={"parameters": parameters})
    return content


def test_calibration_headline():
    texts = [finding.text for finding in calibration_findings(_calibration_content())]
    assert texts == [
        "The sampler converged: largest autocorrelation time 46 steps, largest split R-hat 1.008, smallest "
        "effective sample size 8045.",
        "Estimates, median [90 % credible interval]: mesh stiffness scale 0.969 [0.965, 0.973]; backlash 2b "
        "0.295 mm [0.22, 0.376]; k1 1.01 GN/m [1.008, 1.012].",
        "Not identifiable from these data (posterior close to its prior): backlash 2b (90 % interval spans 87 % "
        "of the prior range).",
        "Posterior predictive check with the real model passed: 99 % of the 72 features within 2 sigma (noise and "
        "model error) of the data, largest |z| 2.32."]
    unconverged = calibration_findings(_calibration_content(converged=False))
    assert unconverged[0].text == "NOT converged, so the estimates are not a result: split R-hat 1.271 > 1.01."
    assert [finding.topic for finding in unconverged] == ["convergence", "predictive_check"]


def test_calibration_headline_says_what_the_pitch_error_correction_did():
    content = _calibration_content()
    content["pitch_errors"] = {"applied": True, "reason": "ISO 1328-1 classes 6 to 8 as stated", "draws": 4,
                               "max_abs_log_shift": 0.191, "median_abs_log_shift": 0.0042, "max_draw_spread": 0.12,
                               "scale_to_class_7": 1.03, "classes": [6.0, 8.0]}
    finding = next(f for f in calibration_findings(content) if f.topic == "pitch_errors")
    assert finding.text == ("Pitch errors: the observed mesh harmonics were corrected for random pitch errors (ISO "
                            "1328-1 classes 6 to 8 as stated; 4 model draws, largest change 19.1 %, median 0.42 %, "
                            "spread between draws up to 12.0 %, added to the variance).")
    assert finding.facts["scale_to_class_7"] == 1.03
    content["pitch_errors"] = {"applied": False, "reason": "22 of 864 sidebands stand 3 noise std above"}
    finding = next(f for f in calibration_findings(content) if f.topic == "pitch_errors")
    assert finding.text == "Pitch errors: no correction (22 of 864 sidebands stand 3 noise std above)."


def test_diagnosis_headline_with_partial_and_borderline_flags():
    content = {
        "verdict": "bearing_clearance", "reason": "bearing_clearance gains 182 nats", "partial": True,
        "remaining_gap": {"value": 1.4}, "rig": {"n_op": 8},
        "borderline": [{"figure": "shrink_fraction", "value": 0.45, "threshold": 0.5, "interval": [0.3, 0.6]}],
        "gap": {"baseline": 2.6, "baseline_interval": [2.4, 2.8], "with_effect": 1.4, "effect": "bearing_clearance",
                "effect_named": True, "shrink_fraction": 0.45, "shrink_interval": [0.3, 0.6], "noise_threshold": 0.5},
        "where": [{"channel": "acc_pinion", "feature": "low_band_rms", "family": "low_frequency", "ops": [0, 3],
                   "score": 12.5}],
    }
    texts = [finding.text for finding in diagnosis_findings(content)]
    assert texts == [
        "At a glance: bearing_clearance (partial: part of the gap remains) (borderline: shrink fraction 0.45 "
        "against 0.5, 90 % interval 0.3 to 0.6); evidence on acc_pinion at run 0 and run 3; next: record more "
        "runs to confirm, then measure the clearance of the bearing.",
        "Verdict bearing_clearance: adding bearing_clearance to the model explains part of the gap between model "
        "and rig; bearing_clearance gains 182 nats.",
        "Held-out gap (RMS standardised discrepancy in excess of noise) of the nominal model 2.60 (90 % interval "
        "2.40 to 2.80); with bearing_clearance 1.40: a shrink of 45 % (90 % interval 30 % to 60 %); within noise "
        "below 0.5.",
        "The nominal model misses most at acc_pinion low_band_rms (low frequency family, beyond 3 sigma at 2 of 8 "
        "runs, RMS z 12.5).",
        "Partial explanation: a held-out gap of 1.40 remains unexplained after bearing_clearance.",
        "Borderline: shrink_fraction = 0.45 against a threshold of 0.5; its 90 % interval 0.3 to 0.6 contains the "
        "threshold, so another campaign of the same rig could be decided the other way."]


def test_a_study_with_calibration_and_diagnosis_results_gets_their_headline():
    diagnosis = {"verdict": "none", "reason": "within noise", "partial": False, "borderline": [], "where": [],
                 "gap": {"baseline": 0.1, "noise_threshold": 0.5}}
    results = [xr.Dataset(attrs={"analysis_type": "calibrate", "analysis_name": "calibration",
                                 "calibration": json.dumps(_calibration_content())}),
               xr.Dataset(attrs={"analysis_type": "diagnose", "analysis_name": "diagnosis",
                                 "diagnosis": json.dumps(diagnosis)})]
    findings = headline_findings(results)
    assert [f.topic for f in findings] == ["convergence", "estimates", "identifiability", "predictive_check",
                                           "at_a_glance", "verdict", "gap", "where", "borderline"]
    assert findings[4].text == ("At a glance: none (sure: no deciding figure is near its threshold); the held-out "
                                "gap is within noise; next: nothing to do: the gear behaves as modelled.")
    assert findings[5].text == ("Verdict none: the nominal model reproduces the rig within noise, no effect is "
                                "needed; within noise.")


# the main job's headline (the t2_envelope study) is checked on the README's run of it: tests/test_readme.py
