"""Sound failure: bad campaigns refused up front, internal failures said to be ours.

* A campaign with no usable signal (all NaN, all zero, shorter than one
  pinion revolution, no or a single operating point) is refused by
  ``uqgear diagnose`` and ``uqgear calibrate`` with exit status 2 and one
  line, before any work (the feature extraction is made to fail if reached).
* Valid data without a line above the noise floor gets the verdict
  ``inconclusive`` with its reason, never ``none``, and no fit.
* A failure inside the work, after the input was accepted, exits with 1, names
  the step, says it is internal and keeps what was finished (``failure.json``
  and the outputs written so far).
* No internal proposal leaves its bounds: the fits' parameter transforms,
  the fits driven to their bounds, the calibration's priors and boxes.

The bad campaigns are the bundled ``healthy.nc`` changed with xarray and
written with :func:`uqgear.write_rig` (the one without operating points
with plain xarray: the format refuses to write it).
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
from dataclasses import replace
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
import xarray as xr
from helpers import candidate_score
from test_cli import TINY  # the tiny in-process study of the CLI tests

import uqgear
from uqgear.calibration import CalibrationError, estimator, posterior_fit, prior_bounds
from uqgear.calibration.likelihood import StageLikelihood
from uqgear.calibration.training import train_emulators
from uqgear.cli import main
from uqgear.common.errors import InternalError, RigDataError, UqgearError, internal_step
from uqgear.common.steps import FAILURE_RECORD, StepLog
from uqgear.diagnosis import VERDICTS, decide
from uqgear.diagnosis import estimator as diagnosis_estimator
from uqgear.diagnosis import nominal as nominal_step
from uqgear.diagnosis import pipeline as diagnosis_pipeline
from uqgear.diagnosis.candidates import ParameterSpec, nominal_parameters
from uqgear.diagnosis.effects import candidates_for, effect_names
from uqgear.diagnosis.fit_problem import FitProblem
from uqgear.diagnosis.fitting import fit
from uqgear.diagnosis.heldout import leave_one_out
from uqgear.physics.design import design_key_bounds
from uqgear.physics.effects import EffectError
from uqgear.rig.format import read_rig
from uqgear.rig.usability import check_usable_signal
from uqgear.study import analyses

ROOT = Path(__file__).resolve().parent.parent
HEALTHY = ROOT / "data" / "rig" / "healthy.nc"
CHANNELS = ("te", "acc_pinion", "acc_gear")
ENVIRONMENT = {**os.environ, "UQGEAR_PROGRESS": "0", "MPLBACKEND": "Agg"}


# ---------------------------------------------------------------------------------------------- campaigns


@pytest.fixture(scope="module")
def healthy() -> xr.Dataset:
    return read_rig(HEALTHY)


def _with_channels(ds: xr.Dataset, make) -> xr.Dataset:
    changed = ds.copy(deep=True)
    for name in CHANNELS:
        changed[name] = changed[name].copy(data=make(changed[name].values).astype(np.float32))
    return changed


def _faults(ds: xr.Dataset) -> dict[str, tuple[xr.Dataset, str]]:
    """Faulty campaigns, and what the one line must name."""
    one_usable = ds.copy(deep=True)
    for name in CHANNELS:
        values = one_usable[name].values.copy()
        values[1:] = np.nan
        one_usable[name] = one_usable[name].copy(data=values)
    negative = ds.assign_coords(drive_torque=("op", -ds["drive_torque"].values, ds["drive_torque"].attrs))
    return {
        "all_nan": (_with_channels(ds, lambda v: np.full_like(v, np.nan)), "missing (NaN)"),
        "all_zero": (_with_channels(ds, np.zeros_like), "all zero"),
        "two_samples": (ds.isel(time=slice(0, 2)), "shorter than one pinion revolution"),
        # 0.073 s: less than the 0.1 s of one pinion revolution at 600 rpm
        "short_records": (ds.isel(time=slice(0, 1500)), "shorter than one pinion revolution"),
        "single_operating_point": (ds.isel(op=[3]), "holds 1 operating point"),
        "one_operating_point_with_signal": (one_usable, "only 1 of 8 operating points carry usable signal"),
        "negative_drive_torque": (negative, "drive_torque: expected torques >= 0"),
    }


@pytest.fixture(scope="module")
def bad_campaigns(healthy, tmp_path_factory) -> dict[str, tuple[Path, str]]:
    folder = tmp_path_factory.mktemp("bad_campaigns")
    files = {}
    for name, (ds, message) in _faults(healthy).items():
        files[name] = (uqgear.write_rig(folder / f"{name}.nc", ds), message)
    # a file without operating points: the format's writer refuses it, so it is written directly
    empty = folder / "no_operating_point.nc"
    healthy.isel(op=slice(0, 0)).drop_encoding().to_netcdf(empty, engine="netcdf4")
    files["no_operating_point"] = (empty, "no operating point")
    return files


@pytest.fixture(scope="module")
def noise_only(healthy, tmp_path_factory) -> Path:
    """Valid records of white noise at each channel's level: no line above the noise floor."""
    rng = np.random.default_rng(3)
    ds = _with_channels(healthy, lambda v: rng.standard_normal(v.shape) * float(np.std(v)))
    return uqgear.write_rig(tmp_path_factory.mktemp("noise") / "noise_only.nc", ds)


def _no_work(*args, **kwargs):
    raise AssertionError("the work started: the campaign should have been refused before it")


# ---------------------------------------------------------------------------------------------- refused up front

FAULTS = ["all_nan", "all_zero", "two_samples", "short_records", "single_operating_point",
          "one_operating_point_with_signal", "negative_drive_torque", "no_operating_point"]


@pytest.mark.parametrize("fault", FAULTS)
def test_diagnose_refuses_a_campaign_without_usable_signal_with_one_line(fault, bad_campaigns, tmp_path, capsys,
                                                                         monkeypatch):
    path, message = bad_campaigns[fault]
    monkeypatch.setattr(diagnosis_estimator, "prepare_case", _no_work)
    out = tmp_path / "out"
    assert main(["diagnose", str(path), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("uqgear: error: ") and message in err, err
    assert not out.exists() and not list(tmp_path.glob(".out*"))


# a single operating point is enough for a calibration (the priors hold what one run cannot separate)
@pytest.mark.parametrize("fault", [fault for fault in FAULTS if fault not in
                                   ("single_operating_point", "one_operating_point_with_signal")])
def test_calibrate_refuses_a_campaign_without_usable_signal_with_one_line(fault, bad_campaigns, tmp_path, capsys,
                                                                          monkeypatch):
    path, message = bad_campaigns[fault]
    monkeypatch.setattr(estimator, "observed_features", _no_work)
    out = tmp_path / "out"
    assert main(["calibrate", str(path), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("uqgear: error: ") and message in err, err
    assert not out.exists()


def test_the_real_command_refuses_all_nan_data_in_a_fresh_interpreter(bad_campaigns, tmp_path):
    """All-NaN data must not give the verdict 'none' with exit 0."""
    completed = subprocess.run([sys.executable, "-m", "uqgear", "diagnose", str(bad_campaigns["all_nan"][0]),
                                "--out", str(tmp_path / "out")], env=ENVIRONMENT, capture_output=True, text=True,
                               timeout=300)
    assert completed.returncode == 2
    assert completed.stderr.count("\n") == 1 and "no usable signal" in completed.stderr
    assert "te, acc_pinion, acc_gear" in completed.stderr and not (tmp_path / "out").exists()


def test_usable_signal_check_names_what_it_refuses(healthy):
    assert check_usable_signal(healthy, min_operating_points=2).tolist() == list(range(8))
    partly = healthy.copy(deep=True)
    values = partly["te"].values.copy()
    values[2, 5] = np.nan                      # one missing sample: that run is unusable for te only
    partly["te"] = partly["te"].copy(data=values)
    assert check_usable_signal(partly, min_operating_points=8).size == 8
    stuck = _with_channels(healthy, lambda v: np.full_like(v, 0.25))
    with pytest.raises(RigDataError, match="constant"):
        check_usable_signal(stuck, where="stuck.nc")
    with pytest.raises(RigDataError, match=r"op: the campaign holds 1 operating point; the diagnosis needs at "
                                           r"least 2 \(why\)"):
        check_usable_signal(healthy.isel(op=[0]), min_operating_points=2, purpose="the diagnosis", why="why")


# ---------------------------------------------------------------------------------------------- inconclusive


def test_noise_only_campaign_is_inconclusive_not_none(noise_only, tmp_path, capsys, monkeypatch):
    """Valid data at the noise floor: the verdict says it cannot decide, without fitting noise."""
    monkeypatch.setattr(diagnosis_pipeline, "fit_nominal_model", _no_work)
    out = tmp_path / "out"
    assert main(["diagnose", str(noise_only), "--out", str(out), "--workers", "1"]) == 0
    printed = capsys.readouterr().out
    assert "verdict inconclusive" in printed and "None" not in printed
    content = json.loads((out / "diagnosis.json").read_text())
    assert content["verdict"] == "inconclusive" and content["verdict"] in VERDICTS
    assert "noise floor" in content["reason"] and content["nominal"] is None
    assert max(content["signal"]["strongest_line_snr"]) < content["signal"]["threshold"]
    maps = uqgear.load_result(out / "diagnosis.nc")
    assert maps.attrs["verdict"] == "inconclusive" and "line_snr" in maps
    report = (out / "report.html").read_text()
    assert "Verdict inconclusive" in report and "Held-out gap not measured" in report


def test_a_gap_that_could_not_be_measured_is_inconclusive_never_none():
    strong = candidate_score("friction", 80.0, 0.0, shrink_interval=(0.0, 0.0), gap_with_effect=math.nan)
    for ranking in ([], [strong]):
        decision = decide(math.nan, ranking)
        assert decision.verdict == "inconclusive" and "could not be measured" in decision.reason
    assert decide(0.1, []).verdict == "none"
    assert VERDICTS[-3:] == ("none", "unexplained", "inconclusive")


# ---------------------------------------------------------------------------------------------- internal failures


def test_internal_step_names_the_step_and_passes_the_users_and_the_systems_errors():
    with pytest.raises(InternalError) as caught:
        with internal_step("outer"):
            with internal_step("fit friction"):
                raise EffectError("friction.coefficient: expected a value in [0, 0.3] 1; got 0.30000000000000004")
    error = caught.value
    assert error.step == "fit friction" and not isinstance(error, UqgearError)
    assert error.detail.startswith("EffectError: friction.coefficient") and isinstance(error.cause, EffectError)
    with pytest.raises(PermissionError):
        with internal_step("write"):
            raise PermissionError("read-only folder")
    with pytest.raises(KeyboardInterrupt):
        with internal_step("fit"):
            raise KeyboardInterrupt
    steps = StepLog()
    with steps.step("first") as found:
        found["value"] = 1.5
    with pytest.raises(InternalError) as caught:
        with steps.step("second"):
            raise ZeroDivisionError("float division by zero")
    assert [entry["step"] for entry in caught.value.finished] == ["first"]
    assert caught.value.finished[0]["value"] == 1.5


def test_internal_failure_in_the_diagnosis_exits_1_names_the_step_and_keeps_what_was_done(tmp_path, capsys,
                                                                                           monkeypatch):
    """A proposal past its bound must not end as 'uqgear: error:' blaming the input, with all work lost."""
    def past_its_bound(*args, **kwargs):
        raise EffectError("friction.coefficient: expected a value in [0, 0.3] 1; got 0.30000000000000004")

    monkeypatch.setattr(nominal_step, "fit_nominal", past_its_bound)
    out = tmp_path / "out"
    assert main(["diagnose", str(HEALTHY), "--out", str(out), "--workers", "1"]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "uqgear: error:" not in err
    assert err.startswith("uqgear: internal error during diagnosis step 'fit the nominal model': EffectError: "
                          "friction.coefficient"), err
    assert f"finished outputs kept in {out}" in err and FAILURE_RECORD in err
    record = json.loads((out / FAILURE_RECORD).read_text())
    assert record["internal_error"] and record["failed_step"] == "fit the nominal model"
    assert [step["step"] for step in record["finished_steps"]] == [
        "extract the rig features", "check that the data can decide", "start the worker processes"]
    assert "past_its_bound" in record["traceback"] and record["inputs"]["rig"] == str(HEALTHY)
    assert not list(tmp_path.glob(".out*"))


def test_internal_failure_after_outputs_were_written_keeps_them(noise_only, tmp_path, capsys, monkeypatch):
    from uqgear.report import diagnosis_report

    def broken_report(*args, **kwargs):
        raise TypeError("unsupported format string passed to NoneType.__format__")

    monkeypatch.setattr(diagnosis_report, "write_diagnosis_report", broken_report)
    out = tmp_path / "out"
    assert main(["diagnose", str(noise_only), "--out", str(out), "--workers", "1"]) == 1
    err = capsys.readouterr().err
    assert "internal error during diagnosis step 'write report.html': TypeError" in err
    assert sorted(path.name for path in out.iterdir()) == ["diagnosis.json", "diagnosis.nc", FAILURE_RECORD]
    assert json.loads((out / "diagnosis.json").read_text())["verdict"] == "inconclusive"
    record = json.loads((out / FAILURE_RECORD).read_text())
    assert record["outputs_finished"] == ["diagnosis.json", "diagnosis.nc"]
    assert record["finished_steps"][-1]["step"] == "write diagnosis.json"


def test_internal_failure_in_the_calibration_exits_1_with_the_step(tmp_path, capsys, monkeypatch):
    def failing(*args, **kwargs):
        raise np.linalg.LinAlgError("Singular matrix")

    monkeypatch.setattr(posterior_fit, "search_box", failing)
    out = tmp_path / "out"
    assert main(["calibrate", str(HEALTHY), "--out", str(out), "--workers", "1"]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith(
        "uqgear: internal error during calibration step 'search the posterior box (staged emulators and "
        "sampling)': LinAlgError: Singular matrix"), err
    record = json.loads((out / FAILURE_RECORD).read_text())
    assert record["command"] == "calibration" and record["inputs"]["rig"] == str(HEALTHY)





def test_internal_failure_in_a_study_run_keeps_the_work_for_resume(tmp_path, capsys, monkeypatch):
    def failing(context):
        with internal_step("fit the nominal model"):
            raise ValueError("array must not contain infs or NaNs")

    monkeypatch.setitem(analyses.ANALYSES, "monte_carlo", failing)
    study = tmp_path / "tiny.yaml"
    study.write_text(TINY)
    out = tmp_path / "out"
    assert main(["run", str(study), "--out", str(out), "--quiet"]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "internal error during study run step 'fit the nominal model'" in err
    assert "--resume" in err and (tmp_path / ".out.partial" / "bifurcation.nc").is_file()


# ---------------------------------------------------------------------------------------------- bounds


def test_the_reported_rounding_past_a_bound_is_clipped():
    """0.03 exp(log(0.3 / 0.03)) is 0.30000000000000004: a value just past the bound."""
    friction = candidates_for("friction", uqgear.load_design("locomotive"))[0]
    spec = friction.fitted[0]
    upper = spec.bounds()[1]
    assert spec.centre * math.exp(upper * spec.unit) > spec.upper       # the raw arithmetic overshoots
    assert spec.from_optimiser(upper) == spec.upper == 0.3
    assert friction.make({spec.name: spec.from_optimiser(upper)}).values["coefficient"] == 0.3


def _edge_values(spec: ParameterSpec) -> list[float]:
    """Natural values of optimiser vectors at, one rounding past and a step past each bound."""
    low, high = spec.bounds()
    return [spec.from_optimiser(v) for v in (low, high, np.nextafter(low, -np.inf), np.nextafter(high, np.inf),
                                             low - 0.02, high + 0.02, low - 1.0, high + 1.0)]


@pytest.mark.parametrize("changes", [{}, {"k1": 1e13, "k2": 1e5, "zeta_mesh": 0.0, "ste_amplitude": 0.0},
                                     {"zeta_mesh": 1.0, "ste_amplitude": 5e-4}],
                         ids=["bundled design", "design at its key limits", "damped design with large STE"])
def test_no_parameter_of_any_fit_can_leave_what_its_constructor_accepts(changes):
    design = uqgear.load_design("locomotive").replace(**changes)
    for spec in nominal_parameters(design):
        values = _edge_values(spec)
        assert all(spec.lower <= value <= spec.upper for value in values), spec.name
        if spec.name != "mesh_stiffness_scale":
            valid_lower, valid_upper = design_key_bounds(spec.name)
            assert valid_lower <= spec.lower and spec.upper <= valid_upper
            for value in values:
                design.replace(**{spec.name: value})
    hints = {"eccentricity_pinion": 1.0, "eccentricity_gear": 0.0, "adhesion_frequency": 1e4}
    for effect in effect_names():
        for candidate in candidates_for(effect, design, hints=hints):
            for corner in ("low", "high"):
                values = {}
                for spec in candidate.fitted:
                    edges = _edge_values(spec)
                    values[spec.name] = edges[0 if corner == "low" else 1]
                    for value in edges:
                        candidate.make({**{s.name: s.from_optimiser(0.0) for s in candidate.fitted},
                                        spec.name: value})
                candidate.make(values)


def _stub_model(case, favoured):
    """The case with model features that fit the rig better the larger ``favoured(task)`` is: the optimiser
    runs to a bound."""
    def execute(tasks):
        results = []
        for task in tasks:
            shortfall = 1.0 - favoured(task)
            results.append((case.observed_all[task.op] * (1.0 + 0.05 * shortfall), True))
        return results
    return replace(case, executor=SimpleNamespace(map=execute))


def test_fits_driven_to_the_upper_bounds_never_propose_past_them(healthy_case):
    # friction's coefficient: its upper bound 0.3 is not hit exactly by the log transform's arithmetic
    friction = candidates_for("friction", healthy_case.design)[0]
    case = _stub_model(healthy_case, lambda task: task.effects[0].values["coefficient"] / 0.3)
    problem = FitProblem(case, friction)
    free = np.zeros(problem.size, dtype=bool)
    free[problem.n_global - 1] = True
    # one start on the bound itself (a start grid, a calibration or a clipped Newton step puts it there)
    starts = [problem.vector({"friction.coefficient": 0.03}), problem.vector({"friction.coefficient": 0.3})]
    assert starts[1][problem.n_global - 1] == problem.upper[problem.n_global - 1]
    result = fit(problem, starts, free=free, max_evaluations=20)
    assert result.values["friction.coefficient"] == pytest.approx(0.3, rel=1e-6)
    assert result.values["friction.coefficient"] <= 0.3
    # the held-out predictions step from the optimum and clip to the box: the same edge again
    held = leave_one_out(result)
    assert np.all(held.vectors <= problem.upper) and np.isfinite(held.z).any()
    # a design at the end of its bearing-stiffness range: the fit's k1 stays inside what the design accepts
    stiff = healthy_case.with_design(healthy_case.design.replace(k1=1e13))
    case = _stub_model(stiff, lambda task: math.log10(task.design.k1) - 12.0)
    problem = FitProblem(case, None)
    free = np.zeros(problem.size, dtype=bool)
    free[[spec.name for spec in problem.specs].index("k1")] = True
    result = fit(problem, [problem.vector({"k1": 6e12})], free=free, max_evaluations=20)
    assert 6e12 < result.values["k1"] <= 1e13


def test_calibration_priors_and_boxes_stay_inside_what_the_design_accepts():
    design = uqgear.load_design("locomotive").replace(k1=1e13, ste_amplitude=4e-4, backlash=4.5e-3)
    bounds = prior_bounds(design, ["mesh_stiffness_scale", "zeta_mesh", "backlash", "ste_amplitude", "k1", "k2"])
    assert bounds["k1"] == (6e12, 1e13) and bounds["ste_amplitude"][1] == 5e-4 and bounds["backlash"][1] == 5e-3
    with pytest.raises(CalibrationError, match=r"priors\.k1: expected bounds within \[100000, 1e\+13\]"):
        prior_bounds(design, ["k1"], {"k1": [1e12, 2e13]})
    # a profile-shift prior that makes the pinion's teeth pointed is refused before any model run
    with pytest.raises(CalibrationError, match=r"priors\.x1: the design at x1 = 1\.5 is not a working gear pair"):
        prior_bounds(design, ["x1"], {"x1": [0.2, 1.5]})
    # a negative nominal turns a relative prior around instead of refusing it
    shifted = uqgear.load_design("locomotive").replace(x2=-0.2)
    low, high = prior_bounds(shifted, ["x2"])["x2"]
    assert low == pytest.approx(-0.26) and high == pytest.approx(-0.14)
    # a box whose upper end the arithmetic overshoots (0.03 + 1 (0.3 - 0.03) = 0.30000000000000004)
    likelihood = object.__new__(StageLikelihood)
    likelihood.box_lower, likelihood.box_upper = np.array([0.03]), np.array([0.3])
    assert 0.03 + 1.0 * (0.3 - 0.03) > 0.3
    assert likelihood.to_physical(np.array([[1.0]]))[0, 0] == 0.3
    seen = []

    def run_model(points):
        seen.extend(points)
        return np.ones((len(points), points[0].shape[0], 3))

    train_emulators(np.array([0.03, 0.0]), np.array([0.3, 1.0]), np.random.SeedSequence(1), run_model=run_model,
                    n_global=1, n_op=1, n_training=16, degree=1)
    assert all(np.all((points >= [0.03, 0.0]) & (points <= [0.3, 1.0])) for points in seen)
