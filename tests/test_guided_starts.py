"""Guided starts: windows from continuation, extra starts only inside them, from-rest numbers outside.

Checked against independent references: the continuation's own fold locations and orbits, the
batch integrator run from rest (bit for bit outside the windows), and brute-force up- and
down-sweeps that carry the final state from point to point (the envelope must hold every response
they reach).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import xarray as xr
import yaml

import uqgear
from uqgear.dynamics import Continuation
from uqgear.dynamics.attractors import MultiStart, StartedEvaluator, up_down_sweeps
from uqgear.dynamics.windows import find_windows
from uqgear.physics.integration import BatchEvaluator, samples_from_mapping
from uqgear.study.guided_starts import GuidedStartModel

WET = 21145.589  # N m: T2 on wet rail (mu = 0.15) for the bundled design
RATED = {"drive_torque": 7000.0}
OPTIONS = {"n_periods": 600, "keep_periods": 200}


@pytest.fixture(scope="module")
def design() -> uqgear.Design:
    return uqgear.load_design("locomotive")


@pytest.fixture(scope="module")
def wet_windows(design: uqgear.Design):
    return find_windows(design, (3000.0, 4500.0), {**RATED, "adhesion_torque": WET}, margin=50.0)


def test_windows_hold_every_bifurcation_of_the_branch_and_both_orbits_of_the_hysteresis(design, wet_windows):
    # the continuation on its own (default settings, 1e-5 of the range): every fold and torus point it
    # locates lies in a window, and a speed far from every bifurcation does not
    reference = Continuation("pinion_speed", 3000.0, 4500.0).fit(design, {**RATED, "adhesion_torque": WET})
    located = [b.parameter for b in reference.bifurcations_]
    assert len(located) >= 4
    assert wet_windows.contains(located).all()
    assert not wet_windows.contains([3100.0, 3300.0, 4450.0]).any()
    # between the folds two stable period-1 orbits: started on each, the runs stay on two responses
    states = wet_windows.orbit_states(3650.0)
    assert len(states) == 2
    samples = samples_from_mapping(
        {"pinion_speed": [3650.0] * 2, "adhesion_torque": [WET] * 2, **{"drive_torque": [7000.0] * 2}}
    )
    runs = uqgear.simulate_batch(design, samples, initial_states=np.array(states), **OPTIONS)
    low, high = sorted(runs["peak_mesh_force"].values)
    assert high > 1.3 * low


def test_a_window_between_two_nodes_is_covered_where_it_drifts_across_the_speed_axis(design):
    # the fold pair moves from about 3930 rpm (33.8 kN m) to 4010 rpm (37 kN m): between the nodes the
    # windows join the nearest windows of both nodes, so the fold pair at 35.4 kN m lies inside
    found = find_windows(
        design, (3500.0, 4500.0), RATED, node_parameter="adhesion_torque", node_values=[33835.0, 37000.0], margin=10.0
    )
    middle = Continuation("pinion_speed", 3500.0, 4500.0).fit(design, {**RATED, "adhesion_torque": 35400.0})
    folds = [b.parameter for b in middle.bifurcations_ if b.kind == "fold"]
    assert len(folds) == 2
    assert found.contains(folds, [35400.0, 35400.0]).all()


def test_outside_the_windows_the_guided_model_gives_the_from_rest_numbers_bit_for_bit(design, wet_windows):
    speeds = [2000.0, 3100.0, 3600.0, 3650.0, 3700.0, 4450.0]
    samples = samples_from_mapping(
        {"pinion_speed": speeds, "adhesion_torque": [WET] * len(speeds), "drive_torque": [7000.0] * len(speeds)}
    )
    rest = BatchEvaluator(design, **OPTIONS)
    started = StartedEvaluator(design, OPTIONS, full_regime=False)

    class Counted:
        def __init__(self, model):
            self.model, self.runs, self.design = model, 0, design

        def __call__(self, batch):
            self.runs += batch.sizes["sample"]
            return self.model(batch)

    model = GuidedStartModel(Counted(rest), Counted(started), design, MultiStart(guided=True, seeded=1), wet_windows, 5)
    out = model(samples)
    alone = rest(samples)
    inside = wet_windows.contains(speeds)
    assert inside.tolist() == [False, False, True, True, True, False]
    for name in ("peak_mesh_force", "dte_rms", "fraction_separation"):
        assert np.array_equal(out[name].values[~inside], alone[name].values[~inside])
        assert np.array_equal(out[f"{name}_rest"].values, alone[name].values)
        # the worst response is never below the one from rest
        assert np.all(out[name].values >= alone[name].values - 1e-9 * np.abs(alone[name].values))
    assert out["attractor_count"].values[~inside].tolist() == [1, 1, 1]
    # 3600 and 3650 rpm hold the low and the high period-1 response (the continuation's two orbits)
    assert out["attractor_count"].values[2:4].tolist() == [2, 2]
    forces = np.sort(out["attractor_peak_mesh_force"].values[3])
    assert forces[1] > 1.3 * forces[0]
    assert out["peak_mesh_force_max_start"].values[3] != "rest"
    assert model.window_points == 3
    assert model.started.runs > 0


def test_guided_starts_are_the_default_of_a_study_and_can_be_switched_off():
    from uqgear.study.schema import study_from_mapping

    raw = yaml.safe_load((Path(uqgear.__file__).parent / "data" / "studies" / "smoke.yaml").read_text())
    raw.get("simulation", {}).pop("starts", None)
    starts = study_from_mapping(raw).simulation.starts
    assert starts is not None and starts.guided
    raw.setdefault("simulation", {})["starts"] = False
    assert study_from_mapping(raw).simulation.starts is None
    raw["simulation"]["starts"] = True
    assert not study_from_mapping(raw).simulation.starts.guided
    raw["simulation"]["starts"] = "guided"
    assert study_from_mapping(raw).simulation.starts.guided


@pytest.mark.parametrize(
    ("starts", "message"),
    [
        ("guidd", r"simulation\.starts: expected guided, true, false or a mapping"),
        ("{guided: yes please}", r"simulation\.starts\.guided: expected true or false"),
        ("{guided: true, nodes: 0}", r"simulation\.starts\.nodes: expected an integer in \[1, 64\]"),
        ("{guided: true, nodes: 2.5}", r"simulation\.starts\.nodes: expected an integer"),
        ("{guided: true, margin: -5}", r"simulation\.starts\.margin: expected a number of rpm in \[0, 2000\]"),
    ],
)
def test_wrong_guided_settings_are_refused_naming_the_key(starts, message):
    from uqgear.common.errors import StudyError
    from uqgear.study.schema import parse_study

    text = (Path(uqgear.__file__).parent / "data" / "studies" / "smoke.yaml").read_text()
    raw = yaml.safe_load(text)
    raw["simulation"] = {**raw.get("simulation", {}), "starts": "STARTS"}
    with pytest.raises(StudyError, match=message):
        parse_study(yaml.safe_dump(raw).replace("STARTS", starts))


def test_a_stable_stretch_that_turns_is_split_into_pieces_one_valued_in_speed():
    from uqgear.dynamics.windows import _monotone_pieces

    class Point:
        def __init__(self, speed: float) -> None:
            self.state = np.full(6, speed)

    class Branch:
        period = 1
        points = [Point(v) for v in (1.0, 2.0, 3.0, 2.5, 2.0, 4.0)]

    parameters = np.array([p.state[0] for p in Branch.points])
    pieces = _monotone_pieces(Branch, parameters, 0, 5)
    assert [piece.speeds.tolist() for piece in pieces] == [[1.0, 2.0, 3.0], [2.0, 2.5, 3.0], [2.0, 4.0]]
    # each piece interpolates the state of its own stretch (here the state is the speed)
    assert [float(piece.state_at(2.75)[0]) for piece in pieces[:2]] == [2.75, 2.75]
    assert pieces[2].state_at(2.75)[0] == pytest.approx(2.75)
    assert pieces[0].state_at(3.5) is None


@pytest.mark.slow
def test_the_main_study_envelope_holds_every_response_the_sweeps_reach(tmp_path, design):
    """The bifurcation envelope of the main study (guided default) at both ends of the T2 interval against
    up- and down-sweeps every 25 rpm from 3000 to 4800 rpm that carry the final state from point to point."""
    studies = Path(uqgear.__file__).parent / "data" / "studies"
    raw = yaml.safe_load((studies / "t2_envelope.yaml").read_text())
    raw["analyses"] = [a for a in raw["analyses"] if a["name"] == "bifurcation_envelope"]
    raw["analyses"][0]["operating_points"]["pinion_speed"] = {"start": 3000, "stop": 4800, "num": 73}
    path = tmp_path / "study.yaml"
    path.write_text(yaml.safe_dump(raw))
    uqgear.run_study(uqgear.load_study(path), tmp_path / "out")
    result = xr.open_dataset(tmp_path / "out" / "bifurcation_envelope.nc")
    speeds = result["pinion_speed"].values
    ends = result["adhesion_torque"].values[[0, -1]]
    # the other uncertain parameters at the midpoints the analysis held them at
    fixed = {k: v for k, v in json.loads(result.attrs["fixed_inputs"]).items() if k != "drive_torque"}
    samples = samples_from_mapping(
        {
            "pinion_speed": np.tile(speeds, 2),
            "adhesion_torque": np.repeat(ends, speeds.size),
            "drive_torque": np.full(2 * speeds.size, 7000.0),
            **{name: np.full(2 * speeds.size, value) for name, value in fixed.items()},
        }
    )
    sweeps = up_down_sweeps(StartedEvaluator(design, OPTIONS), samples)
    rest = BatchEvaluator(design, **OPTIONS)(samples)
    reached = np.maximum.reduce(
        [
            rest["peak_mesh_force"].values,
            sweeps["up"]["peak_mesh_force"].values,
            sweeps["down"]["peak_mesh_force"].values,
        ]
    ).reshape(2, speeds.size)
    envelope = result["peak_mesh_force"].transpose("adhesion_torque", "pinion_speed").values[[0, -1]]
    # a torus or a chaotic response sampled over 200 periods shows a peak that varies by a per cent or two
    short = envelope < 0.97 * reached
    assert not short.any(), [(float(speeds[j]), float(ends[i])) for i, j in zip(*np.nonzero(short))]
    assert int((result["attractor_count"] > 1).sum()) >= 3


def test_starts_beyond_the_sweeps_go_only_where_a_branch_folds_doubles_or_loses_stability():
    from uqgear.dynamics.windows import CoexistenceWindows, NodeWindows, Window

    # node 1: a fold window and a grazing window at the end of the speeds followed; node 2: the fold window
    # moved on and a torus window with no counterpart at node 1
    nodes = (
        NodeWindows(1.0, (Window(3000.0, 3200.0, ("fold",)), Window(5900.0, 6000.0, ("grazing_separation",))), (), ()),
        NodeWindows(2.0, (Window(3100.0, 3300.0, ("fold",)), Window(3600.0, 3900.0, ("neimark_sacker",))), (), ()),
    )
    windows = CoexistenceWindows("adhesion_torque", nodes, 50.0, (2000.0, 6000.0))
    speeds, values = [3250.0, 5000.0, 5950.0, 3750.0], [1.5] * 4
    # every window joined with the nearest of the other node: the grazing window's hull spans 3600-6000 rpm
    assert windows.contains(speeds, values).tolist() == [True, True, True, True]
    # joined with counterparts only, and grazing alone does not count
    assert windows.branching(speeds, values).tolist() == [True, False, False, True]


def test_the_compiled_hausdorff_distance_is_scipys_bit_for_bit():
    from scipy.spatial.distance import directed_hausdorff

    from uqgear.dynamics.attractors import hausdorff

    rng = np.random.default_rng(3)
    for size in ((1, 5), (40, 40), (200, 7)):
        a, b = rng.normal(size=(size[0], 2)), rng.normal(size=(size[1], 2)) + 0.3
        assert hausdorff(a, b) == max(directed_hausdorff(a, b)[0], directed_hausdorff(b, a)[0])


def test_the_branches_are_the_responses_of_the_node_where_coexisting_forces_differ_most():
    """A constructed table of two sweep points x three nodes: the branches come from the node with two responses
    whose peak forces differ most, NaN where no node holds two; the report says both values and where."""
    from uqgear.report.coexistence_sections import branch_sentences
    from uqgear.study.guided_starts import _branches

    grid = np.array([[20e3], [25e3], [30e3]])
    rows = np.array([0, 1, 2, 4])  # point 0: every node; point 1: its middle node only
    found = xr.Dataset(
        {
            "attractor_count": ("sample", [2, 2, 1, 1]),
            "peak_mesh_force_max": ("sample", [150e3, 180e3, 170e3, 160e3]),
            "peak_mesh_force_min": ("sample", [140e3, 110e3, 170e3, 160e3]),
            "dte_rms_max": ("sample", [20e-6, 30e-6, 25e-6, 22e-6]),
            "dte_rms_min": ("sample", [19e-6, 12e-6, 25e-6, 22e-6]),
        }
    )
    out = xr.Dataset(coords={"pinion_speed": [3600.0, 3700.0]})
    out.update(_branches(found, rows, grid, {"adhesion_torque": "N m"}, ["dte_rms"], (2,), ("pinion_speed",)))
    pair = out["dte_rms_branches"].transpose("pinion_speed", "branch").values
    np.testing.assert_array_equal(pair[0], [12e-6, 30e-6])  # node 1: 180 - 110 kN beats 150 - 140 kN
    assert np.isnan(pair[1]).all()  # one response at its only in-window node
    assert out["branch_adhesion_torque"].values[0] == 25e3 and np.isnan(out["branch_adhesion_torque"].values[1])
    assert out["branch_adhesion_torque"].attrs["units"] == "N m"
    (sentence,) = branch_sentences(out, "dte_rms", "pinion_speed")
    assert "at 3600 rpm" in sentence and "T2 = 25 kN m" in sentence and "12 µm or 30 µm" in sentence


def test_a_sweep_entering_a_window_from_outside_follows_the_sweep_over_the_whole_grid(design):
    """Sweeps over the window points alone, entered with the from-rest final states of the points just outside
    (one response there), reach what up- and down-sweeps over the whole grid reach; entered from nothing, the
    down-sweep starts from rest at the window's last point and stays on the lower branch."""
    from uqgear.dynamics.attractors import FINAL_VARIABLES, MultiStartSearch, with_starts

    speeds = np.array([3550.0, 3600.0, 3650.0, 3700.0])
    grid = samples_from_mapping(
        {"pinion_speed": speeds, "adhesion_torque": np.full(4, WET), "drive_torque": np.full(4, 7000.0)}
    )
    evaluate = StartedEvaluator(design, OPTIONS)
    whole = up_down_sweeps(evaluate, grid)
    window = grid.isel(sample=[1, 2])
    outside = evaluate(with_starts(grid, np.array([0, 3]), np.full((2, 6), np.nan)))
    finals = np.stack([outside[name].values for name in FINAL_VARIABLES], axis=1)
    entry = {"up": np.full((2, 6), np.nan), "down": np.full((2, 6), np.nan)}
    entry["up"][0], entry["down"][1] = finals[0], finals[1]
    settings = MultiStart(seeded=0)
    entered = MultiStartSearch(settings).fit(evaluate, window, design, sweep_entry=entry)
    plain = MultiStartSearch(settings).fit(evaluate, window, design)
    for direction in ("up", "down"):
        reference = whole[direction]["peak_mesh_force"].values[1:3]
        np.testing.assert_allclose(entered.runs_["peak_mesh_force"].sel(start=direction).values, reference, rtol=5e-3)
    # the upper branch that the whole grid's down-sweep carries in from 3700 rpm, missed from rest at 3650 rpm
    high = whole["down"]["peak_mesh_force"].values[1:3]
    assert (high > 1.3 * plain.runs_["peak_mesh_force"].sel(start="down").values).all()
    assert entered.attractors_["attractor_count"].values.tolist() == [2, 2]
    assert plain.attractors_["attractor_count"].values.tolist() == [1, 1]
    assert entered.model_runs_ == plain.model_runs_ + 2  # the entered ends run once more, from the entry


def test_a_sweep_is_cut_where_two_neighbours_lie_farther_apart_than_its_reach(design):
    """Two window stretches far apart along speed (3600-3650 rpm and 4800 rpm, as a single-speed analysis's
    listed speeds give): with a reach the sweep starts afresh past the gap, so 4800 rpm's up-sweep run is its
    rest run and 3650 rpm's down-sweep starts from rest there; without it both carry a state over 1150 rpm."""
    from uqgear.dynamics.attractors import FINAL_VARIABLES, MultiStartSearch

    speeds = np.array([3600.0, 3650.0, 4800.0])
    batch = samples_from_mapping(
        {"pinion_speed": speeds, "adhesion_torque": np.full(3, WET), "drive_torque": np.full(3, 7000.0)}
    )
    evaluate = StartedEvaluator(design, {"n_periods": 200, "keep_periods": 50})
    settings = MultiStart(seeded=0)
    cut = MultiStartSearch(settings).fit(evaluate, batch, design, sweep_reach=100.0)
    whole = MultiStartSearch(settings).fit(evaluate, batch, design)
    assert cut.model_runs_ == whole.model_runs_ - 2
    # 3650 rpm carries its up-sweep state on to 4800 rpm only without the reach
    final_3650 = np.array([cut.runs_[name].sel(start="up").values[1] for name in FINAL_VARIABLES])
    np.testing.assert_array_equal(whole.start_states_["up"][2], final_3650)
    assert np.isnan(cut.start_states_["up"][2]).all() and np.isnan(cut.start_states_["down"][1]).all()
    np.testing.assert_array_equal(cut.start_states_["up"][1], whole.start_states_["up"][1])
    for name in ("peak_mesh_force", "dte_rms"):
        np.testing.assert_array_equal(
            cut.runs_[name].sel(start="up").values[2], cut.runs_[name].sel(start="rest").values[2]
        )


def test_statistics_see_the_worst_or_the_rest_response_as_the_study_chooses(tmp_path):
    """Monte Carlo at 3650 rpm on wet rail, where two responses coexist: `response: worst` sees at every sample
    at least the response from rest and somewhere the upper branch; `response: rest` gives the from-rest study's
    numbers bit for bit; both say which in the result."""
    study = {
        "name": "multi_valued",
        "seed": 3,
        "design": {"name": "locomotive"},
        "operating_points": {"pinion_speed": [3650.0], "drive_torque": 7000.0},
        "uncertain": {"adhesion_torque": {"interval": [21100.0, 21400.0]}},
        "simulation": OPTIONS,
        "analyses": [
            {"type": "monte_carlo", "name": "mc", "samples": 6, "sampling": "halton", "qois": ["peak_mesh_force"]}
        ],
    }
    values = {}
    cases = (("worst", "worst", "guided"), ("rest", "rest", "guided"), ("plain", "worst", False))
    for label, response, starts in cases:
        raw = {**study, "simulation": {**OPTIONS, "starts": starts}}
        raw["analyses"] = [{**study["analyses"][0], "response": response}]
        path = tmp_path / f"{label}.yaml"
        path.write_text(yaml.safe_dump(raw))
        uqgear.run_study(uqgear.load_study(path), tmp_path / label)
        with xr.open_dataset(tmp_path / label / "mc.nc") as result:
            values[label] = result["peak_mesh_force_samples"].values.ravel()
            assert result.attrs["response"] == ("rest" if label != "worst" else "worst")
    np.testing.assert_array_equal(values["rest"], values["plain"])
    assert (values["worst"] >= values["rest"]).all()
    assert (values["worst"] > 1.3 * values["rest"]).any()


def test_a_wrong_response_treatment_is_refused_naming_the_key(tmp_path):
    from uqgear.common.errors import StudyError

    text = (Path(uqgear.__file__).parent / "data" / "studies" / "t2_envelope.yaml").read_text()
    assert "    samples: 128" in text
    path = tmp_path / "study.yaml"
    path.write_text(text.replace("    samples: 128", "    samples: 128\n    response: best", 1))
    expected = r"study.yaml: analyses\[3\]\.response: expected one of worst, rest; got .best."
    with pytest.raises(StudyError, match=expected):
        uqgear.load_study(path)
