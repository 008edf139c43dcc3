"""Studies that look for every response: ``simulation.starts`` and the ``continuation`` analysis.

Through the nonlinear window of the locomotive design (T1 = 7 kN m, 3500-3750 rpm, T2 over the wet
to dry rail interval) a study's worst-case envelope is checked against independent up- and
down-sweeps at every T2 of its grid, and the continuation report's statements are recomputed from
its netCDF file with plain numpy.
"""

from __future__ import annotations

import re

import numpy as np
import pytest

import uqgear
from uqgear.common.errors import StudyError
from uqgear.dynamics import StartedEvaluator
from uqgear.dynamics.attractors import up_down_sweeps
from uqgear.physics.integration import samples_from_mapping
from uqgear.report.continuation_sections import continuation_findings
from uqgear.study import parse_study, run_study
from uqgear.study.settings import SimulationSettings
from uqgear.uq.results import load_result

STUDY = """
name: window
seed: 3
design:
  name: locomotive
operating_points:
  pinion_speed: {start: 3500, stop: 3750, num: 6}
  drive_torque: 7000
uncertain:
  adhesion_torque:
    adhesion_coefficient: [0.15, 0.33]
    axle_load: 23000
    wheel_radius: 0.625
simulation:
  n_periods: 1500
  keep_periods: 300
ANALYSES
"""

ENVELOPE = """
  starts: {seeded: 1}
analyses:
  - type: interval
    parameters: [adhesion_torque]
    points: 3
    qois: [peak_mesh_force, fraction_separation]
"""

CONTINUATION = """
analyses:
  - type: continuation
    parameter: pinion_speed
    envelope: [adhesion_torque]
"""


@pytest.fixture(scope="module")
def design():
    return uqgear.load_design("locomotive")


def test_the_worst_case_envelope_is_never_below_the_up_and_down_sweeps(tmp_path, design):
    study = parse_study(STUDY.replace("ANALYSES", ENVELOPE))
    [path] = run_study(study, tmp_path, show_progress=False)
    envelope = load_result(path)
    speeds = envelope["pinion_speed"].values
    lower, upper = (study.uncertain["adhesion_torque"].lower, study.uncertain["adhesion_torque"].upper)
    simulation = study.analyses[0].simulation
    model = StartedEvaluator(design, {"n_periods": simulation.n_periods, "keep_periods": simulation.keep_periods,
                                      "steps_per_mode": simulation.steps_per_mode})
    worst = np.full(speeds.size, -np.inf)
    for t2 in np.linspace(lower, upper, 3):
        samples = samples_from_mapping({"pinion_speed": speeds, "drive_torque": np.full(speeds.size, 7000.0),
                                        "adhesion_torque": np.full(speeds.size, t2)})
        runs = up_down_sweeps(model, samples)
        worst = np.maximum(worst, np.maximum(runs["up"]["peak_mesh_force"].values,
                                             runs["down"]["peak_mesh_force"].values))
    bound = envelope["peak_mesh_force"].sel(bound="upper").values
    assert np.all(bound >= worst * (1 - 1e-12))
    # at 3600 rpm the worst response comes from the down-sweep on wet rail, not from rest
    at = int(np.nonzero(speeds == 3600.0)[0][0])
    assert str(envelope["peak_mesh_force_start"].sel(bound="upper").values[at]) == "down"
    assert envelope["peak_mesh_force_at_adhesion_torque"].sel(bound="upper").values[at] == pytest.approx(lower)
    assert bool(envelope["coexisting"].values[at])
    assert bound[at] == pytest.approx(176.6e3, rel=5e-3)


def test_continuation_statements_are_true_of_the_netcdf_file(tmp_path):
    study = parse_study(STUDY.replace("ANALYSES", CONTINUATION))
    [path] = run_study(study, tmp_path, show_progress=False)
    ds = load_result(path)
    assert ds.sizes["case"] == 2 and "sweep_peak_mesh_force" in ds
    sentences = [finding.text for finding in continuation_findings([ds])]
    # recomputed with plain numpy: the folds of the wet-rail case bound the coexistence window
    wet = int(np.argmin(ds["case_adhesion_torque"].values))
    kinds = ds["bifurcation_type"].values[wet].astype(str)
    folds = np.sort(ds["bifurcation_parameter"].values[wet][kinds == "fold"])
    assert folds.size == 2
    coexisting = next(text for text in sentences if "two stable responses coexist" in text)
    low, high = (float(v) for v in re.search(r"between (\d+) rpm and (\d+) rpm two", coexisting).groups())
    assert low == pytest.approx(folds[0], abs=0.5) and high == pytest.approx(folds[1], abs=0.5)
    middle = 0.5 * (folds[0] + folds[1])
    stable = ds["stable"].values[wet, 0] == 1
    parameter, force = ds["parameter"].values[wet, 0], ds["peak_mesh_force"].values[wet, 0]
    expected = []
    for mask in (stable & (force < 140e3), stable & (force > 140e3)):
        order = np.argsort(parameter[mask])
        expected.append(np.interp(middle, parameter[mask][order], force[mask][order]) / 1e3)
    stated = [float(v) for v in re.search(r"peak mesh force ([\d.]+) or ([\d.]+) kN", coexisting).groups()]
    np.testing.assert_allclose(stated, expected, rtol=1e-3)
    # separation onset: the first grazing point with separation above it, per case
    onset = next(text for text in sentences if "begin to separate" in text)
    grazing = ds["bifurcation_parameter"].values[wet][(kinds == "grazing_separation")
                                                      & (ds["bifurcation_side"].values[wet] > 0)]
    assert f"{grazing.min():.4g} rpm" in onset
    # the brute-force sweeps jump where the folds are
    values = ds["sweep_value"].values
    for direction, fold in (("up", folds[1]), ("down", folds[0])):
        sweep = ds["sweep_peak_mesh_force"].sel(start=direction).values[wet]
        jump = np.nonzero(np.abs(np.diff(sweep)) / sweep[:-1] > 0.1)[0]
        assert jump.size == 1 and values[jump[0]] <= fold <= values[jump[0] + 1]


def test_starts_are_checked_and_leave_rest_only_results_as_they_were():
    assert "starts" not in SimulationSettings().to_dict()     # analysis keys and checkpoints unchanged
    with pytest.raises(StudyError, match=r"simulation\.starts\.seeded"):
        parse_study(STUDY.replace("ANALYSES", "  starts: {seeded: -1}\nanalyses:\n  - type: simulate\n"))
    with pytest.raises(StudyError, match=r"simulation\.starts\.bogus: unknown key"):
        parse_study(STUDY.replace("ANALYSES", "  starts: {bogus: 1}\nanalyses:\n  - type: simulate\n"))
    study = parse_study(STUDY.replace("ANALYSES", "  starts: true\nanalyses:\n  - type: simulate\n"))
    assert study.analyses[0].simulation.starts.seeded == 2


def test_qoi_envelope_spans_the_attractors_of_a_multi_start_grid():
    import xarray as xr

    from uqgear.uq.envelope import qoi_envelope

    dims = ("pinion_speed", "adhesion_torque")
    grid = xr.Dataset({
        "peak_mesh_force": (dims, [[1.0, 2.0], [3.0, 4.0]]),
        "peak_mesh_force_max": (dims, [[1.0, 2.0], [5.0, 4.0]]),
        "peak_mesh_force_min": (dims, [[1.0, 2.0], [3.0, 4.0]]),
        "peak_mesh_force_max_start": (dims, [["rest", "rest"], ["down", "rest"]]),
        "peak_mesh_force_min_start": (dims, [["rest", "rest"], ["rest", "rest"]]),
        "regime": (dims, [["period-1"] * 2] * 2), "fraction_separation": (dims, [[0.0, 0.0], [0.5, 0.0]]),
    }, coords={"pinion_speed": [3500.0, 3600.0], "adhesion_torque": [21150.0, 46520.0]})
    envelope = qoi_envelope(grid, ["peak_mesh_force"])
    np.testing.assert_array_equal(envelope["peak_mesh_force"].values, [[1.0, 2.0], [3.0, 5.0]])
    assert envelope["peak_mesh_force_start_at_bound"].values[1, 1] == "down"
    assert envelope["peak_mesh_force_adhesion_at_bound"].values[1, 1] == 21150.0
