"""The differential diagnosis against a healthy reference: what changed since it, and which effect explains it.

Condition-monitoring features of both campaigns (:mod:`.features`), the
change test (:mod:`.detection`), the effects scored on the change they
predict (:mod:`.scoring`), the route (:mod:`.route`) and the estimator that
runs it and keeps its records (:class:`~.estimator.ChangeDiagnosis`,
:mod:`.estimator`); docs/model/unmodelled-effects.md section 6.1.
"""

from __future__ import annotations

from .detection import CampaignFeatures, ChangeTest, carry_reference, judge_change, read_campaign
from .estimator import ChangeDiagnosis
from .features import FAMILIES, FEATURES, record_features
from .scoring import ChangeScore, score_change

__all__ = [
    "CampaignFeatures",
    "ChangeDiagnosis",
    "ChangeScore",
    "ChangeTest",
    "FAMILIES",
    "FEATURES",
    "carry_reference",
    "judge_change",
    "read_campaign",
    "record_features",
    "score_change",
]
