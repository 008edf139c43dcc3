"""Validation of the diagnosis on virtual-rig campaigns whose effects are withheld: the blind test.

:mod:`.campaigns` plans the campaigns of a suite and makes them with the
virtual rig (:mod:`.runup_campaigns` those recorded as run-ups and
coast-downs), :mod:`.oracle` judges how visible their effects are
independently of the diagnosis, :mod:`.blind_test` diagnoses them blind and
:mod:`.scores` scores the verdicts. The record of what the diagnosis's rules
were measured on is docs/validation/diagnosis.md.

May import :mod:`uqgear.common`, :mod:`uqgear.physics`, :mod:`uqgear.uq`,
:mod:`uqgear.rig`, :mod:`uqgear.report`, :mod:`uqgear.calibration` and
:mod:`uqgear.diagnosis`.
"""

from __future__ import annotations

from .blind_test import blindtest, diagnose_campaign, planned_campaigns
from .campaigns import (
    HEALTHY,
    PLANS,
    STRENGTHS,
    SUITES,
    CampaignSpec,
    operating_points_of,
    plan_campaigns,
    plan_encoderless,
    plan_real_world,
    rig_campaign,
    second_design,
)
from .foreign_suite import run_foreign_suite
from .oracle import effect_visibility, oracle_gap
from .runup_campaigns import plan_runup
from .scores import blindtest_dataset, set_scores, summarise

__all__ = [
    "blindtest",
    "diagnose_campaign",
    "planned_campaigns",
    "plan_campaigns",
    "plan_real_world",
    "plan_encoderless",
    "plan_runup",
    "rig_campaign",
    "summarise",
    "set_scores",
    "blindtest_dataset",
    "oracle_gap",
    "effect_visibility",
    "second_design",
    "operating_points_of",
    "CampaignSpec",
    "HEALTHY",
    "STRENGTHS",
    "PLANS",
    "SUITES",
    "run_foreign_suite",
]
