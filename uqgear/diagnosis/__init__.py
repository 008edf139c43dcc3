"""Sim-to-real gap diagnosis: where model and rig disagree, which unmodelled effect explains it.

:class:`Diagnosis` is the estimator (settings in ``__init__``, the six
steps of docs/model/unmodelled-effects.md section 6 in ``fit``, results in ``*_``
attributes); :func:`diagnose` fits one and writes its folder. The modules
along its steps:

- the estimator and its inputs: :mod:`.estimator`, :mod:`.inputs`,
  :mod:`.settings` (every threshold and budget), :mod:`.writer`; what a
  fitted estimator holds, set in one place: :mod:`.fitted`;
- steps 3 to 6 in their order, with every loop over the fits and every
  call to the verdict's rules: :mod:`.pipeline`;
- step 1, features: :mod:`.case` (a prepared campaign), :mod:`.simulation`
  (model records and the rig's feature processing), :mod:`.execution`
  (runs on worker processes);
- step 2, predictive distribution: :mod:`.discrepancy`, :mod:`.gap_maps`;
- step 3, fits: :mod:`.candidates` (parameters), :mod:`.fit_problem`,
  :mod:`.fitting`, :mod:`.nominal`, :mod:`.screening`, :mod:`.signatures`,
  :mod:`.side_by_side` (independent fits on threads, their runs together);
- step 4, held-out scoring: :mod:`.heldout`, :mod:`.scoring`;
- step 5, verdict: :mod:`.verdict` (the rules, one rules object per case), :mod:`.first_effect`
  (its record), :mod:`.decision`;
- step 6, several effects: :mod:`.selection`, :mod:`.effect_set` (the set's rule in :mod:`.verdict`);
- the record: :mod:`.result`, :mod:`.outputs`, :mod:`.state`; the named
  effects read back as model inputs: :mod:`.named_effects`;
- the effect families as plug-ins: :mod:`.effects`;
- against a healthy reference, what changed since it (:class:`ChangeDiagnosis`,
  the differential route :class:`Diagnosis` takes by default): :mod:`.change`;
- what a campaign holds that is no effect (line interference, a healthy
  reference, the gears' pitch errors, the sideband phase test): :mod:`.allowances`.

May import :mod:`uqgear.common`, :mod:`uqgear.physics`, :mod:`uqgear.uq`,
:mod:`uqgear.rig`, :mod:`uqgear.report` and :mod:`uqgear.calibration`.
"""

from __future__ import annotations

from .change import ChangeDiagnosis
from .decision import Decision
from .effects import EffectFamily, effect_family, effect_names, register_effect, unregister_effect
from .errors import DiagnosisError
from .estimator import Diagnosis
from .inputs import DiagnosisSeeds
from .named_effects import named_effects
from .result import DiagnosisResult
from .scoring import CandidateScore
from .settings import DiagnosisSettings
from .verdict import EFFECT_NAMES, VERDICTS, VerdictRules, decide, decide_verdict, verdict_rules
from .writer import diagnose, write_diagnosis

__all__ = [
    "Diagnosis",
    "ChangeDiagnosis",
    "DiagnosisSettings",
    "DiagnosisSeeds",
    "named_effects",
    "diagnose",
    "write_diagnosis",
    "decide",
    "decide_verdict",
    "VerdictRules",
    "verdict_rules",
    "Decision",
    "DiagnosisError",
    "DiagnosisResult",
    "CandidateScore",
    "EFFECT_NAMES",
    "VERDICTS",
    "EffectFamily",
    "effect_family",
    "effect_names",
    "register_effect",
    "unregister_effect",
]
