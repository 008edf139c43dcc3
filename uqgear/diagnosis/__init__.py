"""Sim-to-real gap diagnosis: where model and rig disagree, which effect explains it.

Also the blind test that scores the diagnosis on campaigns with withheld effects.

Modules along the data path: :mod:`.simulation` (model records, the rig's
feature processing), :mod:`.discrepancy` (predictive distribution of the
features), :mod:`.candidates` (fitted parameters and candidate effects),
:mod:`.case` (a prepared campaign and its run execution), :mod:`.signatures`
(frequency-locked lines, start hints), :mod:`.fitting`, :mod:`.manufacturing`
(the gears' pitch errors as model error), :mod:`.gear_orders` (that model error scaled
to the rig's own gears, order by order), :mod:`.scoring`
(held-out predictions and the gap), :mod:`.verdict`, :mod:`.sideband_phase`
(an eccentric shaft told from pitch errors by its sidebands' phases),
:mod:`.pipeline` (:func:`run_diagnosis`), :mod:`.result` (what it returns),
:mod:`.outputs` (summary and Dataset),
:mod:`.workflow` (:func:`diagnose`) and :mod:`.blind_test`.

May import :mod:`uqgear.common`, :mod:`uqgear.physics`, :mod:`uqgear.uq`,
:mod:`uqgear.rig`, :mod:`uqgear.report` and :mod:`uqgear.calibration`.
"""

from __future__ import annotations

from .errors import DiagnosisError
from .case import prepare_case
from .verdict import decide, decide_verdict, Decision, EFFECT_NAMES, VERDICTS
from .pipeline import run_diagnosis
from .result import DiagnosisResult
from .workflow import diagnose, diagnosis_result
from .blind_test import (
    blindtest, plan_campaigns, summarise, blindtest_dataset, oracle_gap, CampaignSpec, HEALTHY,
    STRENGTHS, PLANS)

__all__ = [
    'diagnose', 'diagnosis_result', 'run_diagnosis', 'prepare_case', 'decide', 'decide_verdict',
    'Decision', 'DiagnosisError', 'DiagnosisResult', 'EFFECT_NAMES', 'VERDICTS', 'blindtest',
    'plan_campaigns', 'summarise', 'blindtest_dataset', 'oracle_gap', 'CampaignSpec', 'HEALTHY',
    'STRENGTHS', 'PLANS',
]
