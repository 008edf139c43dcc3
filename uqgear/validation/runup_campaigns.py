"""The run-up suite of the blind test: the real-world suite's campaigns recorded as a run-up and a coast-down.

:func:`plan_runup` gives the kinds of :func:`~.campaigns.plan_real_world`
(the same effect families, strengths and draws, the same scatter of the
true parameters, healthy controls) with each campaign recorded as a run-up
and a coast-down over one speed span by
:func:`uqgear.rig.virtual_runup.simulate_runup_campaign`, which the
diagnosis cuts into 8 operating points
(:func:`uqgear.rig.ramp_records.steady_campaign`). :func:`runup_campaign`
makes a planned campaign.

What the speed-varying model cannot take is left out: it has no pitch
errors (:func:`~uqgear.rig.virtual_runup.simulate_runup_campaign` refuses
them), so the real-world kinds whose only nuisance is pitch errors (a lone
run-out on class-7 gears, the class-7 healthy control) have no run-up
counterpart, and the other kinds run without them. A wandering ramp must
keep rising (or falling) for its tachometer to place each speed once: the
real-world low-speed control's +-1 % wander at 2 Hz turns a 1400 rpm ramp
slower than 176 rpm/s back, and a ramp that fast breaks the cutting's 5 %
speed change per segment at 600 rpm, so that control wanders at 0.7 Hz here.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any, cast

import numpy as np
import xarray as xr

from ..diagnosis import DiagnosisError
from ..physics.design import Design
from ..physics.effects import Effect
from ..rig.transfer_path import apply_transfer_path
from ..rig.virtual_rig import DEFAULT_DRIVE_TORQUES
from ..rig.virtual_runup import simulate_runup_campaign
from .campaigns import (
    ACCELEROMETER_NUISANCES,
    DESIGNS,
    ENCODER_NUISANCES,
    MAINS_NOISE_NUISANCES,
    RESONANCE_NUISANCES,
    WANDER_NUISANCES,
    CampaignSpec,
    plan_kinds,
)

#: The run-up suite's test plans: a run-up and a coast-down over the service span, or over the low speeds.
RUNUP_PLAN = "runup"
RUNUP_LOW_SPEED_PLAN = "runup_low_speed"
RAMP_PLANS: tuple[str, ...] = (RUNUP_PLAN, RUNUP_LOW_SPEED_PLAN)

# Speed span (rpm) and rate (rpm/s) of each plan's two ramps. The service span starts at 800 rpm: the
# cutting's segments hold 2 pinion revolutions (0.15 s at 800 rpm) and change speed by at most 5 %, which
# bounds the rate by 0.05 n / 0.15 s (267 rpm/s at 800 rpm, 150 at 600); the +-0.5 % wander at 1.3 Hz
# turns a ramp back where 2 pi f a n exceeds the rate (155 rpm/s at 3800 rpm), so 200 rpm/s serves both.
# The low speeds: 600-1400 rpm at 80 rpm/s, above the +-1 % 0.7 Hz wander's 62 rpm/s at 1400 rpm.
# Such segments hold 0.58 gear revolutions at 821 rpm: too few to resolve the gear-order lines, which is what
# the suite's misses come from (docs/validation/blind-tests.md, "Run-up suite"; benchmarks/runup_segments.py).
_RAMP_SPANS: dict[str, tuple[float, float, float]] = {
    RUNUP_PLAN: (800.0, 3800.0, 200.0),
    RUNUP_LOW_SPEED_PLAN: (600.0, 1400.0, 80.0),
}
# the run-up at the service table's largest drive torque, the coast-down at its smallest
_RAMP_TORQUES: tuple[float, float] = (max(DEFAULT_DRIVE_TORQUES), min(DEFAULT_DRIVE_TORQUES))

_LOW_SPEED: dict[str, object] = {"plan": RUNUP_LOW_SPEED_PLAN}
_RUNUP_KINDS: tuple[tuple[str, tuple[str, ...], dict[str, object]], ...] = (
    # (kind, effects (leading first), nuisances): the real-world kinds without pitch errors
    ("two_effects", ("eccentricity", "tooth_damage"), {}),
    ("two_effects", ("torque_ripple", "tooth_damage"), {}),
    ("two_effects_nuisances", ("eccentricity", "friction"), {**WANDER_NUISANCES, **MAINS_NOISE_NUISANCES}),
    ("resonance_reference", ("eccentricity",), {**RESONANCE_NUISANCES, "reference": True}),
    ("wander", ("tooth_damage",), WANDER_NUISANCES),
    ("control_wander", (), WANDER_NUISANCES),
    ("control_mains_noise", (), MAINS_NOISE_NUISANCES),
    ("control_all_nuisances", (), {**WANDER_NUISANCES, **MAINS_NOISE_NUISANCES}),
    ("control_resonance_reference", (), {**RESONANCE_NUISANCES, "reference": True}),
    ("control_wander_accelerometers", (), {**WANDER_NUISANCES, "relative_noise": 0.03, **ACCELEROMETER_NUISANCES}),
    ("control_low_speed_wander", (), {"speed_wander": [(0.01, 0.7)], "relative_noise": 0.03, **_LOW_SPEED}),
    (
        "control_low_speed_wander_accelerometers",
        (),
        {"speed_wander": [(0.01, 0.7)], "relative_noise": 0.05, **ACCELEROMETER_NUISANCES, **_LOW_SPEED},
    ),
    ("encoder_run_out", (), {**ENCODER_NUISANCES, "expected_verdict": "unexplained"}),
    ("encoder_run_out", ("eccentricity",), ENCODER_NUISANCES),
)

# keys of a kind's nuisances that are not options of the virtual rig
_PLAN_KEYS = ("plan", "expected_verdict")


def ramp_table(plan: str, rate: float | None = None) -> dict[str, np.ndarray]:
    """The ramps of a run-up plan: a run-up and a coast-down over its span (start, stop, rate, torque).

    ``rate`` (rpm/s) replaces the plan's own (benchmarks/runup_segments.py
    compares rates).

    Examples
    --------
    >>> ramp_table("runup")["start_speed"].tolist(), ramp_table("runup")["drive_torque"].tolist()
    ([800.0, 3800.0], [8000.0, 5000.0])
    """
    if plan not in _RAMP_SPANS:
        raise DiagnosisError(f"plan: expected one of {', '.join(RAMP_PLANS)}; got {plan!r}")
    low, high, own_rate = _RAMP_SPANS[plan]
    rate = own_rate if rate is None else float(rate)
    return {
        "start_speed": np.array([low, high]),
        "stop_speed": np.array([high, low]),
        "rate": np.array([rate, rate]),
        "drive_torque": np.array(_RAMP_TORQUES),
    }


def plan_runup(n_per_kind: int, rng: np.random.Generator, *, designs: Sequence[str] = DESIGNS) -> list[CampaignSpec]:
    """The run-up suite: the real-world kinds recorded as a run-up and a coast-down (module docstring).

    Per kind ``n_per_kind`` campaigns alternating the designs; effects drawn
    as in :func:`~.campaigns.plan_real_world` (the leading one at its
    ladder's strong level, a second strong or medium), true nominal
    parameters scattered as there. Each campaign's plan is
    :data:`RUNUP_PLAN` (800 -> 3800 rpm and back at 200 rpm/s, 8 and 5 kN m)
    or, for the low-speed controls, :data:`RUNUP_LOW_SPEED_PLAN`
    (600 -> 1400 rpm and back at 80 rpm/s).

    Examples
    --------
    >>> import numpy as np
    >>> from uqgear.validation.runup_campaigns import plan_runup
    >>> specs = plan_runup(1, np.random.default_rng(0))
    >>> len(specs), specs[0].identifier, specs[0].plan, specs[0].truth_set()
    (14, 'runup-two_effects-eccentricity+tooth_damage-0', 'runup', ['eccentricity', 'tooth_damage'])
    """
    return plan_kinds(_RUNUP_KINDS, n_per_kind, rng, designs=designs, default_plan=RUNUP_PLAN, prefix="runup-")


def runup_campaign(
    spec: CampaignSpec,
    design: Design,
    truth: Mapping[str, float],
    effects: Sequence[Effect],
    seed: np.random.SeedSequence,
    title: str,
    rate: float | None = None,
) -> xr.Dataset:
    """A run-up suite campaign from the virtual rig, with the spec's nuisances (transfer path last).

    ``rate`` (rpm/s) replaces the plan's ramp rate (:func:`ramp_table`).
    """
    options: dict[str, Any] = {
        key: value for key, value in spec.nuisances.items() if key not in ("transfer_path", "reference")
    }
    rig = simulate_runup_campaign(
        design,
        ramp_table(spec.plan, rate),
        true_parameters=dict(truth),
        effects=effects,
        seed=seed,
        title=title,
        **options,
    )
    if "transfer_path" in spec.nuisances:
        frequency, damping = cast(tuple[float, float], spec.nuisances["transfer_path"])
        rig = apply_transfer_path(rig, "acc_pinion", frequency, damping)
    return rig


__all__ = ["RUNUP_PLAN", "RUNUP_LOW_SPEED_PLAN", "RAMP_PLANS", "ramp_table", "plan_runup", "runup_campaign"]
