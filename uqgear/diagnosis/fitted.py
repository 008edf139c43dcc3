"""What a fitted diagnosis holds: one frozen record, from which an estimator sets every fitted attribute at once.

Both diagnosis estimators (:class:`~uqgear.diagnosis.Diagnosis` and the
differential :class:`~uqgear.diagnosis.change.estimator.ChangeDiagnosis`)
end their ``fit`` with a :class:`DiagnosisFit` and set their ``*_``
attributes from it through :meth:`FittedState._adopt`; a diagnosis that
hands its work to another estimator takes over that estimator's record the
same way. The time the diagnosis took is measured here too.
"""

from __future__ import annotations

import math
import resource
import time
from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import xarray as xr

from ..common.steps import StepLog
from ..physics.design import Design
from .case import RigCase
from .decision import Decision
from .effect_set import SelectedEffect
from .errors import DiagnosisError
from .fitting import FitResult
from .result import DiagnosisResult
from .scoring import CandidateScore

if TYPE_CHECKING:  # the differential route's record; its module imports this one's users
    from typing import Self

    from .change.route import ChangeOutcome


def cpu_seconds() -> float:
    """CPU time of this process and of its finished worker processes, s."""
    own = resource.getrusage(resource.RUSAGE_SELF)
    children = resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + children.ru_utime + children.ru_stime


def total_timings(timings: Mapping[str, float], started: float, cpu_started: float, workers: int) -> dict[str, float]:
    """The stages' seconds with the whole diagnosis's wall and CPU time and the worker count.

    ``started`` is a :func:`time.perf_counter` reading and ``cpu_started``
    a :func:`cpu_seconds` one, both taken when the diagnosis began.

    Examples
    --------
    >>> import time
    >>> from uqgear.diagnosis.fitted import cpu_seconds, total_timings
    >>> timings = total_timings({"change_test": 0.5}, time.perf_counter(), cpu_seconds(), 2)
    >>> sorted(timings), timings["workers"]
    (['change_test', 'total_cpu', 'total_wall', 'workers'], 2.0)
    """
    return dict(
        timings,
        total_wall=time.perf_counter() - started,
        total_cpu=cpu_seconds() - cpu_started,
        workers=float(workers),
    )


@dataclass(frozen=True)
class DiagnosisFit:
    """Everything a fitted diagnosis holds, as its fitted attributes read it.

    Attributes
    ----------
    design : Design
        The nominal design.
    steps : StepLog
        The finished steps with what they found.
    features : RigCase
        The campaign as compared after step 1 (features, line interference, a reference's correction).
    case : RigCase
        The campaign the verdict was reached on (with the pitch-error allowance where it applies).
    decision : Decision
        The verdict, its reason and the figures that decided it.
    summary : dict
        The JSON-ready record (``diagnosis.json``).
    result : xarray.Dataset
        The record's data (``diagnosis.nc``).
    outcome : DiagnosisResult or None
        Everything the model's fits found (None where no model was fitted).
    change : ChangeOutcome or None
        The change test and the effects' scores on it (a differential diagnosis; else None).
    """

    design: Design
    steps: StepLog
    features: RigCase
    case: RigCase
    decision: Decision
    summary: dict[str, Any]
    result: xr.Dataset
    outcome: DiagnosisResult | None = None
    change: ChangeOutcome | None = None

    @property
    def nominal(self) -> FitResult | None:
        """The nominal model's fit (None where no model was fitted)."""
        return self.outcome.nominal if self.outcome is not None else None

    @property
    def ranking(self) -> tuple[CandidateScore, ...]:
        """The best variant of each candidate effect, best first (none where no model was fitted)."""
        return tuple(self.outcome.scores) if self.outcome is not None else ()

    @property
    def effects(self) -> tuple[SelectedEffect, ...]:
        """The named effects in order (none where no model was fitted)."""
        return tuple(self.outcome.selected) if self.outcome is not None else ()

    @property
    def remaining_gap(self) -> float:
        """The held-out gap the final model leaves (NaN where no model was fitted)."""
        return self.outcome.remaining_gap if self.outcome is not None else math.nan


class FittedState:
    """The fitted attributes of a diagnosis estimator, all set at once from a :class:`DiagnosisFit`.

    Attributes
    ----------
    fitted_ : DiagnosisFit
        Everything found, in one frozen record; the attributes below read it.
    nominal_, ranking_, effects_, decision_, remaining_gap_, summary_, result_, outcome_, change_ : see DiagnosisFit
        Its ``nominal``, ``ranking`` (a list), ``effects`` (a list), ``decision``,
        ``remaining_gap``, ``summary``, ``result``, ``outcome`` and ``change``.
    features_, case_, design_, steps_ : see DiagnosisFit
        Its ``features``, ``case``, ``design`` and ``steps``.
    """

    fitted_: DiagnosisFit
    outcome_: DiagnosisResult | None
    nominal_: FitResult | None
    change_: ChangeOutcome | None = None
    ranking_: list[CandidateScore]
    effects_: list[SelectedEffect]
    decision_: Decision
    remaining_gap_: float
    summary_: dict[str, Any]
    result_: xr.Dataset
    features_: RigCase
    case_: RigCase
    design_: Design
    steps_: StepLog

    def _adopt(self, fitted: DiagnosisFit) -> Self:
        """Set every fitted attribute from one record (the only place they are set); returns ``self``."""
        self.fitted_ = fitted
        self.design_, self.steps_ = fitted.design, fitted.steps
        self.features_, self.case_ = fitted.features, fitted.case
        self.outcome_, self.nominal_, self.change_ = fitted.outcome, fitted.nominal, fitted.change
        self.ranking_, self.effects_ = list(fitted.ranking), list(fitted.effects)
        self.decision_, self.remaining_gap_ = fitted.decision, fitted.remaining_gap
        self.summary_, self.result_ = fitted.summary, fitted.result
        return self

    def to_dict(self) -> dict[str, Any]:
        """The diagnosis as a JSON-ready mapping (the content of ``diagnosis.json``)."""
        if not hasattr(self, "summary_"):
            raise DiagnosisError("diagnosis: not fitted yet; call fit(rig) first")
        return self.summary_


__all__ = ["DiagnosisFit", "FittedState", "cpu_seconds", "total_timings"]
