"""The verdict's rules for one case: its thresholds and what the case's model error lets a gap say.

One :class:`VerdictRules` is built per case by :func:`verdict_rules`, from
the settings and the case as step 3 left it, and every rule of the verdict
reads it. A case is one of three:

``plain``
    The model error is the features' noise model: a gap above ``noise_gap``
    that a candidate shrinks speaks for it.
``pitch_errors``
    The model error holds the pitch-error allowance (the gears' stated
    classes, docs/model/unmodelled-effects.md section 6.4): it widens the
    error of every sideband, so a gap within noise speaks for no effect and
    an effect must carry the evidence by itself; the first effect may be
    named on its held-out density alone (``density_evidence``), and a
    run-out is judged against the first-order run-out the classes make
    (``run_out_bounds``).
``reference``
    Against a healthy reference (section 6.1): an effect is named on the
    share of the change since the reference it explains.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

from ..errors import DiagnosisError
from ..settings import DEFAULT_SETTINGS, ChangeSettings, DiagnosisSettings, VerdictSettings

if TYPE_CHECKING:
    from ..case import RigCase

#: The cases a verdict is reached in.
CASES: tuple[str, ...] = ("plain", "pitch_errors", "reference")


@dataclass(frozen=True)
class VerdictRules:
    """The rules every verdict of one case is reached by (module docstring).

    Attributes
    ----------
    case : str
        ``plain``, ``pitch_errors`` or ``reference``.
    thresholds : VerdictSettings
        The verdict's thresholds (``settings.verdict``).
    change : ChangeSettings
        The change route's shares (``settings.change``), read in the ``reference`` case.
    density_evidence : bool
        In the ``pitch_errors`` case only: a score whose 90 % lower bound
        reaches ``score_threshold`` stands in for a shrink interval above
        zero (the first effect's rules; an effect added on top of others
        must shrink a gap that is there, :meth:`shrink_only`).
    run_out_bounds : tuple of (str, float)
        Per shaft: the first-order run-out the gears' stated pitch-error
        classes make (95 %, m); empty without the allowance.

    Examples
    --------
    >>> rules = verdict_rules()
    >>> rules.case, rules.pitch_allowance, rules.thresholds.score_threshold
    ('plain', False, 10.0)
    """

    case: str
    thresholds: VerdictSettings
    change: ChangeSettings
    density_evidence: bool = False
    run_out_bounds: tuple[tuple[str, float], ...] = ()

    def __post_init__(self) -> None:
        if self.case not in CASES:
            raise DiagnosisError(f"VerdictRules: case {self.case!r} is not one of {', '.join(CASES)}")
        if self.density_evidence and not self.pitch_allowance:
            raise DiagnosisError(
                "VerdictRules: density_evidence stands in for a gap only under the pitch-error allowance; "
                "expected case 'pitch_errors' with it"
            )

    @property
    def pitch_allowance(self) -> bool:
        """Whether the model error holds the pitch-error allowance."""
        return self.case == "pitch_errors"

    def run_out_bound(self, shaft: str) -> float | None:
        """The first-order run-out the stated classes make on ``shaft`` (None: no bound there)."""
        return dict(self.run_out_bounds).get(shaft)

    def shrink_only(self) -> VerdictRules:
        """These rules without the density route: an effect must shrink a gap that is there.

        The rules for an effect added on top of others, and for asking
        whether the candidates leave a gap open.
        """
        return replace(self, density_evidence=False)


def verdict_rules(
    settings: DiagnosisSettings = DEFAULT_SETTINGS, case: RigCase | str | None = None
) -> VerdictRules:
    """The rules of one case, built from the settings and the case.

    Parameters
    ----------
    settings : DiagnosisSettings
        The thresholds.
    case : RigCase, str or None
        The campaign as step 3 left it (``pitch_errors`` where its model
        error holds the pitch-error allowance, else ``plain``), the name of
        a case, or None (``plain``).

    Returns
    -------
    VerdictRules

    Examples
    --------
    >>> verdict_rules(case="pitch_errors").density_evidence
    True
    >>> verdict_rules(case="pitch_errors").shrink_only().density_evidence
    False
    """
    bounds: Mapping[str, float] = {}
    if case is None:
        name = "plain"
    elif isinstance(case, str):
        name = case
    else:
        name = "plain" if case.pitch_allowance is None else "pitch_errors"
        bounds = case.run_out_allowance
    return VerdictRules(
        name,
        settings.verdict,
        settings.change,
        density_evidence=name == "pitch_errors",
        run_out_bounds=tuple(bounds.items()),
    )


#: The rules of a plain case with the documented thresholds.
DEFAULT_RULES = verdict_rules()


__all__ = ["CASES", "VerdictRules", "verdict_rules", "DEFAULT_RULES"]
