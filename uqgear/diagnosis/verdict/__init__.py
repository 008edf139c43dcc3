"""The verdict's rules in one place: one rules object per case, and the rules that read it.

:func:`verdict_rules` builds the :class:`VerdictRules` of a case once, from
the settings and the case as step 3 left it: ``plain``, ``pitch_errors``
(the model error holds the pitch-error allowance) or ``reference`` (against
a healthy reference). Every decision on a gap is made by the rules below,
each reading that object:

- :mod:`.rules`: the rules object and its factory;
- :mod:`.named`: whether a candidate is named on its held-out scores
  (:func:`decide`, the run-out check, whether it leads a set);
- :mod:`.cross_channel`: what an effect predicts per channel against what
  the rig shows;
- :mod:`.sets`: the decision on a set of effects;
- :mod:`.reference`: the change since a healthy reference.

The steps of :class:`~uqgear.diagnosis.Diagnosis` call these rules; the
rules call no step (docs/model/unmodelled-effects.md section 6, steps 5
and 6, sections 6.1, 6.2 and 6.4).
"""

from __future__ import annotations

from ..decision import Decision
from .cross_channel import ChannelCheck, ChannelEvidence, check_channels
from .named import (
    EFFECT_NAMES,
    VERDICTS,
    decide,
    decide_verdict,
    holds_against_pitch_errors,
    leads_a_set,
    ranked,
    run_out_check,
    score_lower_bound,
)
from .reference import decide_change
from .rules import CASES, DEFAULT_RULES, VerdictRules, verdict_rules
from .sets import lead_decision, phase_named_decision, set_decision, unled_decision

__all__ = [
    "CASES",
    "DEFAULT_RULES",
    "VerdictRules",
    "verdict_rules",
    "EFFECT_NAMES",
    "VERDICTS",
    "Decision",
    "decide",
    "decide_verdict",
    "ranked",
    "run_out_check",
    "score_lower_bound",
    "holds_against_pitch_errors",
    "leads_a_set",
    "ChannelCheck",
    "ChannelEvidence",
    "check_channels",
    "set_decision",
    "lead_decision",
    "unled_decision",
    "phase_named_decision",
    "decide_change",
]
