"""Tooth root and flank stresses as QoIs of the batch model and of every QoI analysis.

References: ISO 6336's static stresses at a crawl (the rating, independent of the dynamics), the
one-sample integrator's history of the same run reduced by ``tooth_stresses`` (an independent path
through the model: the pair loads in numpy from the DTE history), and the interval analysis's bounds
against the stresses of its own scan nodes.

The batch reads the pair loads at its RK4 grid steps (here 32 to 76 a mesh period). A history of the
same grid gives the same stresses to rounding; a finer one (4 times as many steps, every fourth
sample on the batch's grid) sees the loads between the batch's grid steps as well, where the peak of
a pair's load can fall (its entry and exit are not grid points, and the flank term changes with
the contact point): there the stresses of these runs differ by 0.1 to 0.55 %, within
:data:`FINER_TOLERANCE`.
"""

from __future__ import annotations

import numpy as np
import pytest
import xarray as xr

import uqgear
from uqgear.cli import main
from uqgear.dynamics.attractors import StartedEvaluator
from uqgear.dynamics.stress_qois import STRESS_QOIS, StressEvaluator, tooth_stress_qois
from uqgear.dynamics.tooth_loads import tooth_stresses
from uqgear.physics.integration import STATE_NAMES, integrate_fast, steps_per_period
from uqgear.physics.rating import RatingSettings, static_rating
from uqgear.study.settings import SimulationSettings

DESIGN = uqgear.load_design("locomotive")
RUN = {"n_periods": 60, "keep_periods": 20}
#: Largest relative difference of a stress QoI between the batch's grid and a history four times finer
#: (module text: 0.55 % measured on these runs, 0.7 % at eight times finer)
FINER_TOLERANCE = 1e-2


def _one_at_a_time(samples: xr.Dataset, rating: RatingSettings, states=None, finer: int = 1) -> np.ndarray:
    """(sample, QoI) stresses of each run integrated alone by the one-sample kernel, in STRESS_QOIS order, from
    its history at ``finer`` times the batch's steps per mesh period (1: the batch's own grid)."""
    rows = []
    for i in range(samples.sizes["sample"]):
        values = {name: float(samples[name].values[i]) for name in samples.data_vars}
        torque = values.get("drive_torque", DESIGN.operation.drive_torque)
        setup = uqgear.build_model(DESIGN, values["pinion_speed"], torque, values["adhesion_torque"])
        start = setup.static_state() if states is None else states[i].copy()
        per_period = finer * steps_per_period(setup, 24)
        history, _, _ = integrate_fast(setup, RUN["n_periods"], RUN["keep_periods"], per_period, 24, start)
        iso = static_rating(DESIGN, torque, values["pinion_speed"], rating, dynamic_factor=1.0)
        first = RUN["n_periods"] - RUN["keep_periods"]
        stresses = tooth_stresses(
            setup, iso, history[:, 2], history[:, 5], first_period=first, samples_per_period=per_period
        )
        rows.append(
            [float(stresses[q].sel(gear=g)) for q, g in (name.rsplit("_", 1) for name in STRESS_QOIS)]
        )
    return np.array(rows)


def test_at_a_crawl_without_transmission_error_the_peaks_are_isos_static_stresses():
    samples = uqgear.samples_from_mapping(
        {"pinion_speed": [5.0, 5.0], "drive_torque": [7000.0, 5000.0], "ste_amplitude": [0.0, 0.0]}
    )
    # a mesh stiffness without jumps: the Ishikawa table's jump where a pair leaves sets the mesh ringing
    # even at a crawl, and the batch, which reads every grid step, sees that overshoot (rating.md 10.6)
    qois = tooth_stress_qois(DESIGN, samples, n_periods=30, keep_periods=10, stiffness="constant")
    for i, torque in enumerate((7000.0, 5000.0)):
        iso = static_rating(DESIGN, torque, 5.0, dynamic_factor=1.0)
        for g, gear in enumerate(("pinion", "gear")):
            # the whole static load on one pair at the outer point of single pair contact: ISO's sigma_F
            assert float(qois[f"root_stress_peak_{gear}"][i]) == pytest.approx(iso.root_stress[g], rel=5e-3)
            # the flank peaks at least at ISO's single pair value (Z_B, Z_D); a pair entering at the pinion's
            # root with load (no tip relief) can raise the pinion's above it
            assert float(qois[f"contact_stress_peak_{gear}"][i]) > iso.contact_stress[g] * (1 - 5e-3)
            # a tooth's stress rises from zero and falls back: its amplitude is half its peak
            peak = float(qois[f"root_stress_peak_{gear}"][i])
            assert float(qois[f"root_stress_amplitude_{gear}"][i]) == pytest.approx(0.5 * peak, rel=1e-12)


def test_the_batch_gives_each_run_the_stresses_of_its_one_sample_history():
    rating = RatingSettings.from_mapping({"face_load_factor": 1.3, "rack_fillet_coefficient": 0.3})
    samples = uqgear.samples_from_mapping(
        {"pinion_speed": [1500.0, 3000.0, 3600.0, 4400.0], "adhesion_torque": [21e3, 33.8e3, 25e3, 46e3]}
    )
    batch = tooth_stress_qois(DESIGN, samples, rating=rating, steps_per_mode=24, **RUN)
    values = np.stack([batch[name].values for name in STRESS_QOIS], axis=1)
    # the history on the batch's own grid: the same pair loads, to rounding
    assert values == pytest.approx(_one_at_a_time(samples, rating), rel=1e-12)
    # a finer history: the loads between the grid steps too (module text)
    finer = _one_at_a_time(samples, rating, finer=4)
    assert values == pytest.approx(finer, rel=FINER_TOLERANCE)
    assert not np.allclose(values, finer, rtol=1e-6, atol=0.0)
    threaded = tooth_stress_qois(DESIGN, samples, rating=rating, steps_per_mode=24, threads=2, **RUN)
    assert all(np.array_equal(batch[name].values, threaded[name].values) for name in STRESS_QOIS)
    for name in STRESS_QOIS:
        assert batch[name].attrs["units"] == "Pa"


def test_the_stress_evaluator_adds_the_stresses_and_keeps_the_batch_qois_bit_for_bit():
    fixed = {"pinion_speed": 3000.0, "drive_torque": 7000.0}
    samples = uqgear.samples_from_mapping({"adhesion_torque": [21e3, 33.8e3, 46e3]})
    plain = uqgear.BatchEvaluator(DESIGN, fixed=fixed, **RUN)(samples)
    evaluator = StressEvaluator(DESIGN, fixed=fixed, **RUN)
    with_stresses = evaluator(samples)
    for name in plain.data_vars:
        assert np.array_equal(plain[name].values, with_stresses[name].values, equal_nan=True), name
    full = samples.assign(pinion_speed=("sample", [3000.0] * 3), drive_torque=("sample", [7000.0] * 3))
    direct = tooth_stress_qois(DESIGN, full, steps_per_mode=24, **RUN)
    for name in STRESS_QOIS:
        assert np.array_equal(with_stresses[name].values, direct[name].values)
    # the rating inputs change the stresses, so they are part of the checkpoint key
    other = StressEvaluator(DESIGN, fixed=fixed, rating=RatingSettings(face_load_factor=1.4), **RUN)
    assert other.key() != evaluator.key() and evaluator.key() != uqgear.BatchEvaluator(DESIGN, fixed=fixed, **RUN).key()


def test_a_started_run_gives_the_stresses_of_its_own_start():
    samples = uqgear.samples_from_mapping({"pinion_speed": [3600.0, 3600.0], "adhesion_torque": [25e3, 25e3]})
    setup = uqgear.build_model(DESIGN, 3600.0, DESIGN.operation.drive_torque, 25e3)
    states = np.stack([setup.static_state(), setup.static_state() + np.array([0, 0, 4e-5, 0, 0, 0.05])])
    started = samples.assign({f"initial_{name}": ("sample", states[:, j]) for j, name in enumerate(STATE_NAMES)})
    options = {**RUN, "steps_per_mode": 24}
    result = StartedEvaluator(DESIGN, options, 0, full_regime=False, stresses=RatingSettings())(started)
    alone = _one_at_a_time(samples, RatingSettings(), states)
    assert np.stack([result[name].values for name in STRESS_QOIS], axis=1) == pytest.approx(alone, rel=1e-12)


def test_simulation_settings_carry_the_stress_inputs_through_their_plain_values():
    settings = SimulationSettings(stresses=RatingSettings.from_mapping({"material": {"sigma_Flim": 4.3e8}}))
    again = SimulationSettings(**settings.to_dict())
    assert again == settings and isinstance(again.stresses, RatingSettings)
    assert "stresses" not in SimulationSettings().to_dict()


STUDY = """
name: stress_check
seed: 5
design: {name: locomotive}
operating_points:
  pinion_speed: [1500, 3600]
  drive_torque: 7000
uncertain:
  adhesion_torque: {adhesion_coefficient: [0.15, 0.33], axle_load: 23000, wheel_radius: 0.625}
simulation: {n_periods: 60, keep_periods: 20, steps_per_mode: 24, starts: false}
analyses:
  - type: interval
    name: stresses
    method: scan
    points: 3
    qois: [peak_mesh_force, root_stress_peak_pinion, contact_stress_amplitude_gear]
    rating: {face_load_factor: 1.2}
"""


def test_an_interval_analysis_bounds_a_stress_by_its_scan_nodes(tmp_path):
    (tmp_path / "study.yaml").write_text(STUDY)
    assert main(["run", str(tmp_path / "study.yaml"), "--out", str(tmp_path / "out"), "--quiet"]) == 0
    with xr.open_dataset(tmp_path / "out" / "stresses.nc") as result:
        result = result.load()
    t2 = 23000 * 9.80665 * 0.625 * np.array([0.15, 0.24, 0.33])
    rating = RatingSettings(face_load_factor=1.2)
    for speed in (1500.0, 3600.0):
        samples = uqgear.samples_from_mapping(
            {"pinion_speed": [speed] * 3, "drive_torque": [7000.0] * 3, "adhesion_torque": t2}
        )
        nodes = tooth_stress_qois(DESIGN, samples, rating=rating, steps_per_mode=24, **RUN)
        for name in ("root_stress_peak_pinion", "contact_stress_amplitude_gear"):
            bounds = result[name].sel(pinion_speed=speed).values
            assert result[name].attrs["units"] == "Pa"
            assert bounds == pytest.approx([float(nodes[name].min()), float(nodes[name].max())], rel=1e-12)


def test_a_monte_carlo_analysis_samples_a_stress(tmp_path):
    text = STUDY.split("  - type: interval")[0] + (
        "  - type: monte_carlo\n    samples: 8\n    qois: [root_stress_peak_gear]\n"
    )
    (tmp_path / "study.yaml").write_text(text)
    assert main(["run", str(tmp_path / "study.yaml"), "--out", str(tmp_path / "out"), "--quiet"]) == 0
    with xr.open_dataset(tmp_path / "out" / "monte_carlo.nc") as result:
        drawn = result["root_stress_peak_gear_samples"].values
        stats = result["root_stress_peak_gear"].load()
    assert np.all((drawn > 1e8) & (drawn < 1e9)) and stats.attrs["units"] == "Pa"


BAD = [
    ("    qois: [root_stress_peak]\n", "analyses[0].qois[0]: expected one of"),
    ("    qois: [peak_mesh_force]\n    rating: {face_load_factor: 1.2}\n", "analyses[0].rating: only the tooth"),
    ("    qois: [root_stress_peak_gear]\n    rating: {face_load_factor: 0.5}\n", "analyses[0].rating.face_load_factor"),
]


@pytest.mark.parametrize("lines, message", BAD)
def test_bad_stress_input_exits_2_with_one_line_and_writes_nothing(tmp_path, capsys, lines, message):
    text = STUDY.split("    qois:")[0] + lines
    (tmp_path / "study.yaml").write_text(text)
    assert main(["run", str(tmp_path / "study.yaml"), "--out", str(tmp_path / "out")]) == 2
    captured = capsys.readouterr()
    assert message in captured.err and captured.err.count("\n") == 1
    assert not (tmp_path / "out").exists()


def test_a_simulate_analysis_runs_the_studys_effects_and_gives_the_stresses_along_the_path(tmp_path):
    text = (
        "name: stress_path\nseed: 2\ndesign: {name: locomotive}\n"
        "model:\n  effects:\n    tooth_damage: {depth: 0.3}\n"
        "operating_points: {pinion_speed: [2500], drive_torque: 7000, adhesion_torque: 33800}\n"
        "simulation: {n_periods: 60, keep_periods: 20, steps_per_mode: 24}\n"
        "analyses:\n  - type: simulate\n    rating: {face_load_factor: 1.25}\n"
    )
    (tmp_path / "study.yaml").write_text(text)
    assert main(["run", str(tmp_path / "study.yaml"), "--out", str(tmp_path / "out"), "--quiet"]) == 0
    with xr.open_dataset(tmp_path / "out" / "simulate.nc") as result:
        run = result.isel(run=0).load()
    effect = uqgear.make_effect("tooth_damage", {"depth": 0.3})
    alone = uqgear.simulate(DESIGN, 2500.0, 7000.0, 33800.0, n_periods=60, keep_periods=20, effects=[effect])
    assert np.array_equal(run["x"].values, alone["x"].values)
    setup = uqgear.build_model(DESIGN, 2500.0, 7000.0, 33800.0, effects=[effect])
    iso = static_rating(DESIGN, 7000.0, 2500.0, RatingSettings(face_load_factor=1.25), dynamic_factor=1.0)
    stresses = tooth_stresses(
        setup, iso, alone["x"].values, alone["x_velocity"].values, first_period=40, samples_per_period=64
    )
    upper = stresses["root_stress"].max("engagement").values
    assert run["root_stress_path"].sel(bound="upper").values == pytest.approx(upper, rel=1e-12)
    assert float(run["root_stress_peak_pinion"]) == pytest.approx(float(upper[0].max()), rel=1e-12)
    assert run["contact_stress_path"].attrs["units"] == "Pa" and run.sizes["position"] == upper.shape[1]


def test_a_bad_rating_block_of_a_simulate_analysis_exits_2_with_one_line(tmp_path, capsys):
    text = (
        "name: stress_path\nseed: 2\ndesign: {name: locomotive}\n"
        "operating_points: {pinion_speed: [2500], drive_torque: 7000, adhesion_torque: 33800}\n"
        "analyses:\n  - type: simulate\n    rating: {rack_fillet_coefficient: 2.0}\n"
    )
    (tmp_path / "study.yaml").write_text(text)
    assert main(["run", str(tmp_path / "study.yaml"), "--out", str(tmp_path / "out")]) == 2
    captured = capsys.readouterr()
    assert "analyses[0].rating.rack_fillet_coefficient" in captured.err and captured.err.count("\n") == 1
    assert not (tmp_path / "out").exists()
