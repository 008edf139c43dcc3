"""The ``rating`` analysis: ISO 6336 safety factors and damage from the simulated dynamic load, in a study.

A tiny study (two speeds, short runs, T2 bounded by a first-order Chebyshev
inclusion) runs once; its ``rating.nc`` is checked against the static rating
it is built from: the lower safety factor is the static one at the upper
simulated dynamic factor, ISO's K_v curve is method B's, and the damage is
the service's hours times the damage rates of the rainflow-counted tooth
stress histories, which are checked against a count of a one-sample run.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
import xarray as xr

import uqgear
from uqgear.cli import main
from uqgear.physics.rating import RatingSettings, dynamic_factor_model, static_rating

STUDY = """
name: rating_check
seed: 3
design: {name: locomotive}
operating_points:
  pinion_speed: [1500, 4000]
  drive_torque: 7000
uncertain:
  adhesion_torque: {adhesion_coefficient: [0.15, 0.33], axle_load: 23000, wheel_radius: 0.625}
simulation: {n_periods: 60, keep_periods: 20}
analyses:
  - type: rating
    order: 1
    points: 2
    rating: {material: {sigma_Flim: 1.5e+8, sigma_Hlim: 6.0e+8}}
    service: {hours: 1000, speeds: [1500, 4000], shares: [0.25, 0.75]}
"""
SETTINGS = RatingSettings.from_mapping({"material": {"sigma_Flim": 1.5e8, "sigma_Hlim": 6.0e8}})


@pytest.fixture(scope="module")
def rating(tmp_path_factory):
    folder = tmp_path_factory.mktemp("rating")
    (folder / "study.yaml").write_text(STUDY)
    assert main(["run", str(folder / "study.yaml"), "--out", str(folder / "out")]) == 0
    with xr.open_dataset(folder / "out" / "rating.nc") as ds:
        return ds.load()


def test_the_result_has_the_named_variables_with_dims_and_units(rating):
    dims = {
        "dynamic_factor_iso": ("pinion_speed",),
        "dynamic_factor": ("bound", "pinion_speed"),
        "root_stress_nominal": ("gear",),
        "contact_stress_nominal": ("gear",),
        "safety_factor_root": ("gear", "bound", "pinion_speed"),
        "safety_factor_contact": ("gear", "bound", "pinion_speed"),
        "damage": ("gear", "bound", "mode"),
    }
    for name, expected in dims.items():
        assert rating[name].dims == expected, name
        assert "units" in rating[name].attrs, name
    assert rating["root_stress_nominal"].attrs["units"] == "Pa"
    assert list(rating["mode"].values) == ["root", "contact"]
    design = uqgear.load_design("locomotive")
    model = dynamic_factor_model(design, 7000.0, SETTINGS)
    assert rating.attrs["resonance_speed_iso"] == pytest.approx(model.resonance_speed)
    assert rating["dynamic_factor_iso"].values == pytest.approx(model.factor(np.array([1500.0, 4000.0])))


def test_safety_factors_are_the_static_rating_at_the_simulated_dynamic_factor(rating):
    design = uqgear.load_design("locomotive")
    for j, speed in enumerate([1500.0, 4000.0]):
        upper = float(rating["dynamic_factor"].sel(bound="upper").values[j])
        static = static_rating(design, 7000.0, speed, SETTINGS, dynamic_factor=upper)
        low = rating.isel(pinion_speed=j).sel(bound="lower")
        assert low["safety_factor_root"].values == pytest.approx(static.safety_root)
        assert low["safety_factor_contact"].values == pytest.approx(static.safety_contact)
    assert (rating["safety_factor_root"].sel(bound="lower") <= rating["safety_factor_root"].sel(bound="upper")).all()
    force = rating["peak_mesh_force"] / rating["dynamic_factor"]
    assert force.values == pytest.approx(7000.0 / uqgear.load_design("locomotive").z1 / 0.0045 / np.cos(np.radians(20)))


def test_damage_is_the_service_hours_times_the_damage_rates(rating):
    service = json.loads(rating.attrs["service"])
    assert service["rail"] if "rail" in service else True
    rate = rating["damage_rate"].sel(pinion_speed=service["speeds"])  # the service speeds are sweep speeds
    expected = (rate * xr.DataArray(service["shares"], dims="pinion_speed")).sum("pinion_speed") * service["hours"]
    np.testing.assert_allclose(rating["damage"].values, expected.transpose("gear", "bound", "mode").values, rtol=1e-12)
    assert float(rating["damage"].sel(gear="pinion", bound="upper", mode="root")) > 0.0
    assert (rating["damage"].sel(bound="lower") <= rating["damage"].sel(bound="upper")).all()
    np.testing.assert_allclose(rating["life_hours"], service["hours"] / rating["damage"], rtol=1e-12)
    np.testing.assert_allclose(rating["damage_share"].sum("service_speed"), 1.0)
    assert (rating["root_stress_peak"].sel(bound="upper") >= rating["root_stress_peak"].sel(bound="lower")).all()


def test_damage_over_attractors_is_recorded_and_equals_the_runs_from_rest_where_one_response(rating):
    assert rating.attrs["damage_over_attractors"] == "guided"
    count = rating["history_attractor_count"]
    assert count.dims == ("history_torque", "pinion_speed") and (count >= 1).all()
    assert rating.attrs["history_coexisting_points"] == int((count > 1).sum())
    assert rating["damage_rate_start"].dims == ("gear", "mode", "history_torque", "pinion_speed")
    if int((count > 1).sum()) == 0:
        np.testing.assert_array_equal(rating["damage"].values, rating["damage_from_rest"].values)
        assert (rating["damage_rate_start"] == "rest").all()
    assert (rating["damage"].sel(bound="upper") >= rating["damage_from_rest"].sel(bound="upper")).all()


def test_every_start_searches_the_history_points(tmp_path):
    study = STUDY.replace(
        "simulation: {n_periods: 60, keep_periods: 20}", "simulation: {n_periods: 60, keep_periods: 20, starts: true}"
    )
    (tmp_path / "study.yaml").write_text(study)
    assert main(["run", str(tmp_path / "study.yaml"), "--out", str(tmp_path / "out"), "--quiet"]) == 0
    with xr.open_dataset(tmp_path / "out" / "rating.nc") as ds:
        assert ds.attrs["damage_over_attractors"] == "every start at every history point"
        assert (ds["history_attractor_count"] >= 1).all()
        assert (ds["damage"].sel(bound="upper") >= ds["damage_from_rest"].sel(bound="upper")).all()
        assert (ds["damage"].sel(bound="lower") <= ds["damage_from_rest"].sel(bound="lower")).all()


def test_history_points_and_a_rail_distributions_own_t2_values(tmp_path):
    """``history_points: 5`` runs five T2 values across the interval and the rail distribution's values besides;
    the distribution's damage is then its time-weighted mean of the rates at those values (no interpolation)."""
    from uqgear.study.rating_service import service_damage

    rail = "rail: {adhesion_coefficient: [0.2, 0.3], shares: [0.25, 0.75]}"
    service = f"{{hours: 100, speeds: [1500, 4000], shares: [0.5, 0.5], {rail}}}"
    study = STUDY.replace(
        "    service: {hours: 1000, speeds: [1500, 4000], shares: [0.25, 0.75]}",
        f"    service: {service}\n    history_points: 5",
    )
    (tmp_path / "study.yaml").write_text(study)
    assert main(["run", str(tmp_path / "study.yaml"), "--out", str(tmp_path / "out"), "--quiet"]) == 0
    with xr.open_dataset(tmp_path / "out" / "rating.nc") as ds:
        torques = ds["history_adhesion_torque"].values
    arm = 23000 * 9.80665 * 0.625
    lower, upper = 0.15 * arm, 0.33 * arm
    expected = np.sort(np.concatenate([np.linspace(lower, upper, 5), [0.2 * arm, 0.3 * arm]]))
    np.testing.assert_allclose(torques, expected, rtol=1e-12)
    rates = np.arange(14.0).reshape(7, 2)  # (torque, speed)
    checked = {"hours": 100.0, "speeds": [1500.0, 4000.0], "shares": [0.5, 0.5]}
    checked["rail"] = {"kind": "distribution", "adhesion_coefficient": [0.2, 0.3], "shares": [0.25, 0.75]}
    damage, _ = service_damage(checked, np.array([1500.0, 4000.0]), expected, rates)
    at = [int(np.argmin(abs(expected - t))) for t in (0.2 * arm, 0.3 * arm)]
    mean = 0.25 * rates[at[0]] + 0.75 * rates[at[1]]
    assert damage.tolist() == pytest.approx([100.0 * 0.5 * mean.sum()] * 2, rel=1e-12)


def test_damage_rate_is_the_rainflow_count_of_a_one_sample_run():
    """The batch's damage rate at one (T2, speed) against an independent Miner sum over a one-sample run."""
    from uqgear.dynamics.tooth_loads import tooth_stresses
    from uqgear.study.rating_histories import HISTORY_SAMPLES, history_damage
    from uqgear.study.settings import SimulationSettings

    design = uqgear.load_design("locomotive")
    simulation = SimulationSettings(n_periods=60, keep_periods=20)
    speed, t2 = 3500.0, 38e3
    weak = RatingSettings.from_mapping({"material": {"sigma_Flim": 1.0e8, "sigma_Hlim": 4.0e8}})
    result = history_damage(design, simulation, {"drive_torque": 7000.0}, [speed], [t2], weak)
    run = uqgear.simulate(
        design,
        speed,
        7000.0,
        t2,
        n_periods=60,
        keep_periods=20,
        samples_per_period=HISTORY_SAMPLES,
        steps_per_mode=simulation.steps_per_mode,
    )
    static = static_rating(design, 7000.0, speed, weak, dynamic_factor=1.0)
    setup = uqgear.build_model(design, speed, 7000.0, t2)
    stresses = tooth_stresses(setup, static, run["x"].values, first_period=40, samples_per_period=HISTORY_SAMPLES)
    expected = _miner_rates(design, static, stresses, speed)
    np.testing.assert_allclose(result.rates[:, :, 0, 0], expected, rtol=1e-9, atol=1e-30)
    assert result.rates[0, 0, 0, 0] > 0.0 and result.rates[0, 1, 0, 0] > 0.0
    assert result.peaks[0, 0, 1, 0, 0] == pytest.approx(float(stresses["root_stress_peak"][0]), rel=1e-12)


def _miner_rates(design, static, stresses, speed):
    """(gear, mode) damage per hour of one run's stress tables: rainflow (the ``rainflow`` package) and Basquin
    between the S-N curve's knees, written out here."""
    import rainflow

    rates = np.zeros((2, 2))
    for g, per_revolution in enumerate((1.0, design.z1 / design.z2)):
        for m, (name, curve) in enumerate((("root", static.root_curve[g]), ("contact", static.contact_curve[g]))):
            table = stresses[f"{name}_stress"].values[g]
            history = np.concatenate(([0.0], table.ravel(), [0.0]))
            n_k, s_k = np.asarray(curve.cycles), np.asarray(curve.stress)
            total = 0.0
            for rng, mean, count, _, _ in rainflow.extract_cycles(history):
                peak = mean + rng / 2.0
                if peak <= s_k[-1]:
                    continue
                i = 0 if peak >= s_k[1] else 1
                slope = np.log(n_k[i + 1] / n_k[i]) / np.log(s_k[i] / s_k[i + 1])
                life = 1.0 if peak > s_k[0] else n_k[i] * (s_k[i] / peak) ** slope
                total += count / life
            rates[g, m] = total / table.shape[0] * 60.0 * speed * per_revolution
    return rates


def test_damage_over_two_coexisting_attractors_is_the_worst_ones_count():
    """A point with two attractors (3600 rpm on wet rail): the upper damage rate is the greater of the two
    attractors' rainflow counts, each over a history run in the test from that attractor's first start."""
    from uqgear.dynamics.attractors import MultiStart, MultiStartSearch, StartedEvaluator
    from uqgear.dynamics.tooth_loads import tooth_stresses
    from uqgear.physics.integration import samples_from_mapping
    from uqgear.study.rating_histories import HISTORY_SAMPLES, history_damage
    from uqgear.study.settings import SimulationSettings

    design = uqgear.load_design("locomotive")
    speed, t2, n_periods, keep = 3600.0, 21150.0, 1500, 300
    simulation = SimulationSettings(n_periods=n_periods, keep_periods=keep)
    # the down-sweep from 3700 rpm carries the second branch to 3600 rpm
    samples = samples_from_mapping(
        {"pinion_speed": [speed, 3700.0], "adhesion_torque": [t2] * 2, "drive_torque": [7000.0] * 2}
    )
    search = MultiStartSearch(MultiStart(seeded=0)).fit(
        StartedEvaluator(design, {"n_periods": n_periods, "keep_periods": keep}), samples
    )
    labels = [str(label) for label in search.attractors_["first_start"].values[0] if str(label)]
    assert len(labels) == 2 and labels[0] == "rest"
    starts = [(label, search.start_states_[label][0]) for label in labels]
    weak = RatingSettings.from_mapping({"material": {"sigma_Flim": 1.0e8, "sigma_Hlim": 4.0e8}})
    result = history_damage(
        design, simulation, {"drive_torque": 7000.0}, [speed], [t2], weak, starts=lambda _: [starts]
    )
    assert int(result.attractor_count[0, 0]) == 2 and result.runs == 2
    static = static_rating(design, 7000.0, speed, weak, dynamic_factor=1.0)
    setup = uqgear.build_model(design, speed, 7000.0, t2)
    independent = []
    for label, state in starts:
        run = uqgear.simulate(
            design,
            speed,
            7000.0,
            t2,
            n_periods=n_periods,
            keep_periods=keep,
            samples_per_period=HISTORY_SAMPLES,
            steps_per_mode=simulation.steps_per_mode,
            initial_state=None if label == "rest" else state,
        )
        stresses = tooth_stresses(
            setup, static, run["x"].values, first_period=n_periods - keep, samples_per_period=HISTORY_SAMPLES
        )
        independent.append(_miner_rates(design, static, stresses, speed))
    independent = np.stack(independent)  # (attractor, gear, mode)
    assert not np.allclose(independent[0], independent[1], rtol=1e-3)  # two responses, two damages
    np.testing.assert_allclose(result.rates[:, :, 0, 0], independent[0], rtol=1e-9, atol=1e-30)
    np.testing.assert_allclose(result.rate_bounds[:, :, 1, 0, 0], independent.max(axis=0), rtol=1e-9, atol=1e-30)
    np.testing.assert_allclose(result.rate_bounds[:, :, 0, 0, 0], independent.min(axis=0), rtol=1e-9, atol=1e-30)
    assert (result.rate_bounds[:, :, 1, 0, 0] >= result.rates[:, :, 0, 0]).all()
    assert result.rate_bounds[0, 0, 1, 0, 0] > result.rates[0, 0, 0, 0]  # the pinion root: the second branch's
    worst = np.asarray(labels)[independent.argmax(axis=0)]
    assert (result.worst_start[:, :, 0, 0] == worst).all()


BAD = [
    ("rating: {material: {sigma_Hlim: 1500}}", "analyses[0].rating.material.sigma_Hlim: expected a value in"),
    ("service: {hours: 100, speeds: [1500, 3000], shares: [0.5, 0.4]}", "analyses[0].service.shares: expected time"),
    ("service: {hours: 100, speeds: [1500, 5000], shares: [0.5, 0.5]}", "analyses[0].service.speeds: 5000 rpm is"),
    ("rating: {K_A: 1.2}", "analyses[0].rating.K_A: unknown key"),
    ("service: {hours: 100, speeds: [1500, 3000], shares: [1.2, -0.2]}", "analyses[0].service.shares[0]: expected"),
    ("service: {hours: 100, speeds: [1500], shares: [1], colour: red}", "analyses[0].service.colour: unknown key"),
    (
        "service: {hours: 100, mission: [{pinion_speed: 1500, hours: 60}, {pinion_speed: 3000, hours: 60}]}",
        "analyses[0].service.hours: the mission sums to 120 h; got 100",
    ),
    (
        "service: {hours: 100, speeds: [1500], shares: [1], rail: {adhesion_coefficient: [0.1, 0.2]}}",
        "analyses[0].service.rail.adhesion_coefficient: T2 = 14097.1 N m is outside",
    ),
    ("service: {kilometres: 1.0e+6, speeds: [1500], shares: [1]}", "analyses[0].service.wheel_radius: required"),
    ("service: tram", "analyses[0].service: expected a service mapping or a bundled profile (locomotive)"),
    ("history_points: 1", "analyses[0].history_points: expected an integer in [2, 33]"),
    ("history_points: 2.5", "analyses[0].history_points: expected an integer in [2, 33]"),
]


@pytest.mark.parametrize("line, message", BAD)
def test_bad_rating_input_exits_2_with_one_line(tmp_path, capsys, line, message):
    text = STUDY.split("    rating:")[0] + f"    {line}\n"
    (tmp_path / "study.yaml").write_text(text)
    assert main(["run", str(tmp_path / "study.yaml"), "--out", str(tmp_path / "out")]) == 2
    captured = capsys.readouterr()
    assert message in captured.err and captured.err.count("\n") == 1
    with pytest.raises(uqgear.StudyError, match="a rating sweeps only pinion_speed"):
        uqgear.parse_study(STUDY.replace("drive_torque: 7000", "drive_torque: [6000, 7000]"))


def test_the_verdict_names_the_coexisting_responses_that_raise_the_damage():
    from uqgear.report.rating_sections import rating_verdicts

    gbm = ("gear", "bound", "mode")
    damage = np.array([[[0.0, 0.0], [0.3, 0.0]], [[0.0, 0.0], [0.1, 0.0]]])
    starts = np.full((2, 2, 3, 2), "rest", dtype=object)
    starts[0, 0, 0, 1] = "down"
    ds = xr.Dataset(
        {
            "safety_factor_root": (("gear", "bound", "pinion_speed"), np.full((2, 2, 2), 2.0), {"minimum": 1.4}),
            "damage": (gbm, damage),
            "damage_from_rest": (gbm, damage / 3.0),
            "damage_rate_start": (("gear", "mode", "history_torque", "pinion_speed"), starts.astype(str)),
        },
        coords={"gear": ["pinion", "gear"], "bound": ["lower", "upper"], "mode": ["root", "contact"]}
        | {"pinion_speed": [3000.0, 4200.0]},
        attrs={"service": '{"hours": 20000}'},
    )
    line = rating_verdicts(ds)[0]
    assert line.endswith(
        "(pinion, at least 0 over the rail condition; 0.1 from rest, the rest from coexisting responses at 4200 rpm)"
    ), line
    ds["damage_from_rest"] = ds["damage"]
    assert "coexisting" not in rating_verdicts(ds)[0]


def test_the_verdict_of_a_calibrated_gear_set_says_where_its_worst_speed_lies_beyond_the_campaign():
    from uqgear.report.rating_sections import rating_verdicts

    safety = np.array([[[1.9, 1.3], [2.4, 2.0]], [[2.0, 1.5], [2.6, 2.2]]])  # worst: pinion at 4600 rpm
    ds = xr.Dataset(
        {"safety_factor_root": (("gear", "bound", "pinion_speed"), safety, {"minimum": 1.4})},
        coords={"gear": ["pinion", "gear"], "bound": ["lower", "upper"], "pinion_speed": [3000.0, 4600.0]},
    )
    assert "campaign" not in rating_verdicts(ds)[0]  # no posterior: nothing to be beyond
    ds.attrs["campaign_range"] = '{"pinion_speed": [600.0, 3800.0], "drive_torque": [5000.0, 8000.0]}'
    assert rating_verdicts(ds)[0] == (
        "tooth root: S_F falls to 1.30 (pinion, 4600 rpm) against the required 1.4 (below it), beyond the rig "
        "campaign's 600-3800 rpm (the model, not the rig data, carries it)"
    )
    ds.attrs["campaign_range"] = '{"pinion_speed": [600.0, 4600.0]}'  # the campaign's own top speed is inside
    assert "campaign" not in rating_verdicts(ds)[0]


def test_a_rating_of_the_calibrated_gear_set_records_the_campaign_it_was_learnt_on(tmp_path):
    # a one-point posterior learnt at 600 and 1000 rpm: the rating runs with its medians and keeps its campaign range
    import json

    import uqgear
    from uqgear.report.rating_sections import rating_verdicts

    rows = np.broadcast_to(np.array([1.05, 0.06]), (2, 10, 2)).copy()
    design = uqgear.load_design("locomotive")
    xr.Dataset(
        {"mesh_stiffness_scale": (("chain", "draw"), rows[..., 0]), "zeta_mesh": (("chain", "draw"), rows[..., 1])},
        coords={"pinion_speed": ("op", [600.0, 1000.0]), "drive_torque": ("op", [7000.0, 7000.0]),
                "adhesion_torque_lower": ("op", [25e3, 25e3]), "adhesion_torque_upper": ("op", [40e3, 40e3])},
        attrs={"converged": 1, "parameters": json.dumps(["mesh_stiffness_scale", "zeta_mesh"]),
               "design": design.to_json()},
    ).to_netcdf(tmp_path / "posterior.nc")
    text = f"""
name: rated
seed: 1
operating_points: {{pinion_speed: [2000, 3000], drive_torque: 7000}}
uncertain:
  adhesion_torque: {{interval: [25.0e+3, 40.0e+3]}}
  calibrated: {{posterior: {tmp_path / "posterior.nc"}, draws: 4}}
simulation: {{n_periods: 80, keep_periods: 30, starts: false}}
analyses:
  - {{type: rating, name: rating, method: vertex, history_points: 2}}
"""
    (path,) = uqgear.run_study(uqgear.parse_study(text, base_dir=tmp_path), tmp_path / "out", show_progress=False)
    result = uqgear.load_result(path)
    assert json.loads(result.attrs["campaign_range"])["pinion_speed"] == [600.0, 1000.0]
    assert json.loads(result.attrs["fixed_inputs"])["mesh_stiffness_scale"] == 1.05
    assert all("beyond the rig campaign's 600-1000 rpm" in line for line in rating_verdicts(result))
