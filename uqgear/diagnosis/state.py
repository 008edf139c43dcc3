"""What the steps of one diagnosis share: the campaign, the settings, the candidates and the nominal model."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, replace

import numpy as np

from ..common.steps import StepLog
from .case import RigCase
from .fitting import FitResult
from .heldout import HeldOut
from .settings import DiagnosisSettings
from .verdict.rules import VerdictRules


@dataclass(frozen=True)
class DiagnosisState:
    """The state the steps after the nominal fit share (screening, full fits, forward selection, phase test).

    A new state is made when the nominal fit changes (:meth:`with_nominal`).
    The random stream, the step log and the timings are shared by every
    state of one diagnosis: each step draws from the stream in turn, so the
    order of the steps fixes the numbers.

    Attributes
    ----------
    case : RigCase
        The campaign with every allowance taken in.
    settings : DiagnosisSettings
    rules : VerdictRules
        The verdict's rules of the case (:func:`~.verdict.rules.verdict_rules`), built once from
        the settings and the case.
    effects : tuple of str
        The candidate effect families.
    hints : mapping
        Starting values read off the rig's signature (:func:`~.effects.signature_hints`).
    rng : numpy.random.Generator
        The bootstrap's random stream.
    steps : StepLog
        The finished steps with what they found.
    timings : dict
        Seconds per stage (``timing_s`` of ``diagnosis.json``).
    nominal : FitResult
        The nominal fit.
    nominal_held : HeldOut
        Its held-out predictions.
    nominal_gap : float
        Its held-out gap.
    earlier_full_fits : mapping
        Full fits of candidates (by label) made against an earlier nominal
        fit that stopped in a local optimum: starts of their full fits again.
    """

    case: RigCase
    settings: DiagnosisSettings
    rules: VerdictRules
    effects: tuple[str, ...]
    hints: Mapping[str, float]
    rng: np.random.Generator
    steps: StepLog
    timings: dict[str, float]
    nominal: FitResult
    nominal_held: HeldOut
    nominal_gap: float
    earlier_full_fits: Mapping[str, FitResult] = field(default_factory=dict)

    def with_nominal(self, nominal: FitResult, held: HeldOut, gap: float) -> DiagnosisState:
        """This state with another nominal fit and its held-out predictions."""
        return replace(self, nominal=nominal, nominal_held=held, nominal_gap=gap)


__all__ = ["DiagnosisState"]
