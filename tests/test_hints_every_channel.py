"""Signature hints read off every channel: a campaign without encoders gets its stick-slip start from the housings."""

from __future__ import annotations

import json

import numpy as np
import pytest

from uqgear.diagnosis import signatures
from uqgear.diagnosis.case import prepare_case
from uqgear.diagnosis.effects import effect_family
from uqgear.diagnosis.fit_problem import FitProblem
from uqgear.diagnosis.fitting import start_costs
from uqgear.physics.design import load_design
from uqgear.physics.effects import AdhesionOscillation, Eccentricity
from uqgear.rig.format import make_rig_dataset
from uqgear.rig.virtual_rig import simulate_campaign

FS, SIZE = 20480.0, 20480
SPEEDS = np.array([700.0, 1300.0, 2100.0, 3100.0])
#: The torque oscillation's frequency, fixed in Hz across runs (the known truth the hint must recover).
STICK_SLIP = 17.0


@pytest.fixture(scope="module")
def design():
    return load_design("locomotive")


def _accelerometer(speed: float, rng: np.random.Generator, *, modulation: float, phase: float) -> np.ndarray:
    """A housing's record: the mesh line, amplitude-modulated by a fixed-frequency torque oscillation and by the
    pinion's shaft order (a run-out: its sidebands lie at the speed, so they move between runs), in white noise."""
    time = np.arange(SIZE) / FS
    mesh = 21 * speed / 60.0
    shaft = speed / 60.0
    envelope = 1.0 + modulation * np.cos(2 * np.pi * STICK_SLIP * time + phase) + 0.2 * np.cos(2 * np.pi * shaft * time)
    return envelope * np.cos(2 * np.pi * mesh * time) + 0.05 * rng.standard_normal(SIZE)


def _case(design, channels: dict[str, np.ndarray]):
    lower = np.full(SPEEDS.size, 25000.0)
    rig = make_rig_dataset(time=np.arange(SIZE) / FS, pinion_speed=SPEEDS, drive_torque=np.full(SPEEDS.size, 6000.0),
                           adhesion_torque_lower=lower, adhesion_torque_upper=lower + 5000.0, channels=channels,
                           design=design, title="synthetic", source="test", history="test")
    return prepare_case(rig, design, seed=np.random.SeedSequence(0))


def _accelerometers(modulation: float, seed: int) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(seed)
    def records() -> np.ndarray:
        return np.stack([_accelerometer(s, rng, modulation=modulation, phase=float(rng.uniform(0, 6.28)))
                         for s in SPEEDS])

    return {name: records() for name in ("acc_pinion", "acc_gear")}


def test_an_encoderless_case_gets_the_stick_slip_start_from_the_accelerometers(design):
    # a modulation of 3 % at a fixed 17 Hz: far below the shaft's 20 % sidebands, which move with the speed
    case = _case(design, _accelerometers(0.03, 1))
    assert "te" not in case.channels
    assert signatures.frequency_locked_lines(case) == []
    lines = signatures.steady_modulation_lines(case)
    assert lines[0]["frequency"] == pytest.approx(STICK_SLIP, abs=1.0)
    near = {line["channel"] for line in lines if abs(line["frequency"] - STICK_SLIP) <= 1.0}
    assert near == {"acc_pinion", "acc_gear"}
    # the shaft's order-locked sidebands (11.7 to 51.7 Hz) are no steady line
    assert all(abs(line["frequency"] - STICK_SLIP) <= 1.0 for line in lines)
    hints = signatures.signature_hints(case, signatures.every_channel_locked_lines(case))
    assert hints["adhesion_frequency"] == pytest.approx(STICK_SLIP, abs=1.0)
    # and the fit starts there instead of the default grid
    variant = effect_family("adhesion_oscillation").variants(design, hints)[0]
    assert {start["adhesion_oscillation.frequency"] for start in variant.starts} == {hints["adhesion_frequency"]}


def test_noise_and_order_lines_alone_give_no_hint(design):
    case = _case(design, _accelerometers(0.0, 2))
    assert signatures.steady_modulation_lines(case) == []
    assert "adhesion_frequency" not in signatures.signature_hints(case, signatures.every_channel_locked_lines(case))


def test_a_case_with_a_te_keeps_the_te_hint_and_ignores_the_housings(design):
    rng = np.random.default_rng(3)
    time = np.arange(SIZE) / FS
    te_line = np.stack([2e-6 * np.cos(2 * np.pi * 21 * s / 60 * time) + 3e-7 * np.sin(2 * np.pi * 41.0 * time + s)
                        + 1e-9 * rng.standard_normal(SIZE) for s in SPEEDS])
    housings = _accelerometers(0.03, 4)
    with_line = _case(design, {"te": te_line, **housings})
    hints = signatures.signature_hints(with_line, signatures.every_channel_locked_lines(with_line))
    assert hints["adhesion_frequency"] == pytest.approx(41.0, abs=1.0)
    # a TE without a line in the band: no start is read, the housings' line notwithstanding
    te_plain = np.stack([2e-6 * np.cos(2 * np.pi * 21 * s / 60 * time) + 1e-9 * rng.standard_normal(SIZE)
                         for s in SPEEDS])
    plain = _case(design, {"te": te_plain, **housings})
    lines = signatures.every_channel_locked_lines(plain)
    assert [line["channel"] for line in lines if line["channel"] == "te"] == []
    assert any(abs(line["frequency"] - STICK_SLIP) <= 1.0 for line in lines)
    assert "adhesion_frequency" not in signatures.signature_hints(plain, lines)


def test_lines_without_a_channel_are_the_te_s():
    family = effect_family("adhesion_oscillation")
    assert family.hints({}, [{"frequency": 30.0}, {"frequency": 12.0}]) == {"adhesion_frequency": 12.0}
    assert family.hints({}, [{"frequency": 0.5}, {"frequency": 150.0}]) == {}


def test_the_run_out_start_reads_the_te_first_and_the_housings_sidebands_without_one():
    family = effect_family("eccentricity")
    runs = np.ones(4)
    # a stiffness modulation kappa puts sidebands of kappa / 2 of the mesh line on either side (known truth)
    kappa = 0.004
    housings = {
        "acc_pinion:mesh1": 2.0 * runs,
        "acc_pinion:mesh1_sb_pinion+1": 2.0 * runs * kappa / 2,
        "acc_pinion:mesh1_sb_pinion-1": 2.0 * runs * kappa / 2,
        "acc_pinion:mesh1_sb_gear+1": 1e-6 * runs,
        "acc_pinion:mesh1_sb_gear-1": 1e-6 * runs,
    }
    hints = family.hints(housings, [])
    assert hints["eccentricity_pinion"] == pytest.approx(kappa / family.proportional["kappa"])
    assert hints["eccentricity_gear"] == pytest.approx(1e-6 / family.proportional["kappa"])
    # with a TE the TE's first-order lines alone, as before
    with_te = {**housings, "te:shaft_pinion1": np.array([1e-6, 3e-6, np.nan]), "te:shaft_gear1": np.full(3, np.nan)}
    assert family.hints(with_te, []) == {"eccentricity_pinion": pytest.approx(2e-6)}


#: A weak stick-slip on a rig without encoders whose speed wanders (known truth of the campaign below).
WEAK_STICK_SLIP = {"amplitude": 0.008, "frequency": 17.0, "phase": 1.0}


@pytest.fixture(scope="module")
def wandering_encoderless_case(design):
    """A weak stick-slip at 17 Hz on the housings alone, the pinion speed wandering by +-0.6 % at 1.1 Hz."""
    rig = simulate_campaign(design, effects=[AdhesionOscillation(WEAK_STICK_SLIP)], seed=np.random.SeedSequence(123),
                            channels=("acc_pinion", "acc_gear"), speed_wander=[(0.006, 1.1)])
    adhesion = np.asarray(json.loads(rig.attrs["true_parameters"])["adhesion_torque"], dtype=float)
    return prepare_case(rig, design, seed=np.random.SeedSequence(0)), adhesion


def test_a_wandering_speed_s_own_line_does_not_hide_a_weaker_stick_slip_from_the_starts(
    design, wandering_encoderless_case
):
    case, adhesion = wandering_encoderless_case
    lines = signatures.steady_modulation_lines(case)
    # the wander's frequency modulation of the mesh line is the strongest steady line, not the stick-slip
    assert abs(lines[0]["frequency"] - WEAK_STICK_SLIP["frequency"]) > 5.0
    assert any(abs(line["frequency"] - WEAK_STICK_SLIP["frequency"]) <= 1.0 for line in lines)
    hints = signatures.signature_hints(case, signatures.every_channel_locked_lines(case))
    variant = effect_family("adhesion_oscillation").variants(design, hints)[0]
    frequencies = sorted({start["adhesion_oscillation.frequency"] for start in variant.starts})
    assert any(abs(f - WEAK_STICK_SLIP["frequency"]) <= 1.0 for f in frequencies)
    # the fit keeps the start of least cost: with the true nominal model and T2, one at the stick-slip
    problem = FitProblem(case, variant)
    positions = (adhesion - case.adhesion_lower) / (case.adhesion_upper - case.adhesion_lower)
    costs = start_costs(problem, [problem.vector(start, positions) for start in variant.starts])
    best = variant.starts[int(np.argmin(costs))]["adhesion_oscillation.frequency"]
    assert best == pytest.approx(WEAK_STICK_SLIP["frequency"], abs=1.0)


#: A weak pinion run-out with its stiffness modulation in proportion (4e-4 m per unit), under speed wander.
WEAK_RUN_OUT = {"amplitude": 1.5e-7, "shaft": "pinion", "phase": 2.0, "kappa": 1.5e-7 / 4e-4}


def test_a_weak_run_out_s_modulation_starts_below_the_housings_sideband_reading(design):
    rig = simulate_campaign(design, effects=[Eccentricity(WEAK_RUN_OUT)], seed=np.random.SeedSequence(7),
                            channels=("acc_pinion", "acc_gear"), speed_wander=[(0.006, 1.1)])
    adhesion = np.asarray(json.loads(rig.attrs["true_parameters"])["adhesion_torque"], dtype=float)
    case = prepare_case(rig, design, seed=np.random.SeedSequence(0))
    family = effect_family("eccentricity")
    hints = signatures.signature_hints(case, signatures.every_channel_locked_lines(case))
    # noise and wander add to the sidebands: their reading is well above the true modulation
    reading = hints["eccentricity_pinion"] * family.proportional["kappa"]
    assert reading > 1.5 * WEAK_RUN_OUT["kappa"]
    variant = family.variants(design, hints)[0]
    assert variant.label == "eccentricity[pinion]"
    # the fit keeps the start of least cost: with the true nominal model and T2, one near the true modulation
    problem = FitProblem(case, variant)
    positions = (adhesion - case.adhesion_lower) / (case.adhesion_upper - case.adhesion_lower)
    costs = start_costs(problem, [problem.vector(start, positions) for start in variant.starts])
    best = variant.starts[int(np.argmin(costs))]["eccentricity.kappa"]
    assert WEAK_RUN_OUT["kappa"] / 2 < best < 2 * WEAK_RUN_OUT["kappa"]


def test_a_run_out_read_off_the_te_keeps_its_two_modulation_starts(design):
    family = effect_family("eccentricity")
    hints = family.hints({"te:shaft_pinion1": np.array([2e-6, 2e-6])}, [])
    assert "eccentricity_pinion_sidebands" not in hints
    kappas = sorted({start["eccentricity.kappa"] for start in family.variants(design, hints)[0].starts})
    assert kappas == pytest.approx([1e-9, 2e-6 * family.proportional["kappa"]])
