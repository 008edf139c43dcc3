"""An eccentric shaft told from the gears' own pitch errors by the phases of the mesh lines' first sidebands.

A gear's first-order pitch error and an eccentric shaft's run-out move the
shaft's first-order line alike, and the compared features are amplitudes,
so a run-out of a size the gears' stated classes make is the gear's own to
the fit (:mod:`.pitch_orders`, :func:`.pitch_errors.run_outs_not_told_apart`).
An eccentric shaft also modulates the mesh stiffness, k(t) (1 + kappa
cos(W_s t + phase)), which pitch errors do not: it adds sidebands in a
fixed phase relation to their mesh harmonic. The phase sum

    Q = arg P(n z + 1) + arg P(n z - 1) - 2 arg P(n z)

of the n-th mesh harmonic's first sidebands of that shaft (orders in the
shaft's rotations) does not depend on where the record starts nor on the
eccentricity's phase, and for pitch errors it hardly depends on the draw
(docs/model/unmodelled-effects.md section 6.4). Its distribution is simulated
under the final model with pitch errors of the allowance (H0) and with an
eccentricity of the run-out the fit read (H1), each over the fitted
model's parameter spread, and the rig's phase sums are scored under both
(von Mises densities widened by each sum's own noise). The log ratio is
evidence for an eccentricity that the amplitudes cannot give.

Only a shaft whose sidebands lie at least ``min_sideband_orders`` pinion
orders from their carrier is tested (:class:`~uqgear.diagnosis.DiagnosisSettings`):
nearer, as a gear's sidebands are on the reference design (0.21 pinion
orders), they sit among the gear's other orders, which the line fit does not
hold apart, and the sums mislead (docs/model/unmodelled-effects.md section 6.4, "An eccentric
shaft named by its sidebands' phases"; docs/validation/diagnosis.md).
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Any, ClassVar

import numpy as np
import scipy.special

from ...physics.effects import Eccentricity
from ..case import RigCase
from ..effects import EffectFamily, run_out_family
from ..errors import DiagnosisError
from ..fitting import FitResult, fit_candidate
from ..heldout import HeldOut, leave_one_out
from ..scoring import CandidateScore, score_candidate
from ..settings import DEFAULT_SETTINGS, DiagnosisSettings

#: The fitted model's parameter spread the phase sums are pooled over: each factor up and down.
PARAMETER_SPREAD = {"mesh_stiffness_scale": 1.03, "zeta_mesh": 1.25}
_HARMONICS = (1, 2, 3)


@dataclass(frozen=True)
class ModulationEvidence:
    """The phase-sum test of one shaft (:func:`modulation_evidence`).

    The evidence for each modulation tried is the log ratio summed over the
    phase sums of every operating point but the one that favours the
    eccentricity most: a single run's sums (a resonance crossed, a burst of
    wander) must not name an effect alone.

    Attributes
    ----------
    shaft : str
    run_out : float
        Eccentricity amplitude of the hypothesis: the run-out the fit read off the shaft's first-order lines, m.
    per_sum : dict
        Per kappa of ``settings.phases.modulation_kappas``: (n_op, n_channel, n_harmonic) log density of each of
        the rig's phase sums with the eccentricity minus without it, nats (0 where a sum is not usable).
    n_sums : int
        Phase sums scored (harmonic x channel x operating point with all three lines finite).
    threshold : float
    seconds : float
    """

    shaft: str
    run_out: float
    per_sum: dict[float, np.ndarray] = field(repr=False)
    n_sums: int
    threshold: float = DEFAULT_SETTINGS.phases.phase_evidence_threshold
    seconds: float = 0.0
    #: Its entry in ``diagnosis.json`` (one per shaft tested).
    key: ClassVar[str] = "sideband_phases"

    @property
    def applied(self) -> bool:
        """Whether any phase sum was scored."""
        return self.n_sums > 0

    @classmethod
    def from_sums(
        cls,
        shaft: str,
        run_out: float,
        per_sum: dict[float, np.ndarray],
        n_sums: int,
        *,
        threshold: float = DEFAULT_SETTINGS.phases.phase_evidence_threshold,
        seconds: float = 0.0,
    ) -> ModulationEvidence:
        return cls(
            shaft,
            float(run_out),
            {float(kappa): np.asarray(value, dtype=float) for kappa, value in per_sum.items()},
            int(n_sums),
            threshold,
            seconds,
        )

    @property
    def log_ratios(self) -> dict[float, float]:
        """Per kappa: the log ratio without the most favourable operating point, nats."""
        ratios = {}
        for kappa, value in self.per_sum.items():
            per_op = value.reshape(value.shape[0], -1).sum(axis=1)
            ratios[kappa] = float(per_op.sum() - per_op.max()) if per_op.size else 0.0
        return ratios

    @property
    def kappa(self) -> float:
        """The modulation the phase sums favour most."""
        ratios = self.log_ratios
        return max(ratios, key=lambda kappa: ratios[kappa])

    @property
    def log_ratio(self) -> float:
        return self.log_ratios[self.kappa]

    @property
    def total(self) -> float:
        """The log ratio at :attr:`kappa` over all operating points, nats."""
        return float(self.per_sum[self.kappa].sum())

    @property
    def decisive(self) -> bool:
        """Whether the phase sums name an eccentric shaft."""
        return self.n_sums > 0 and self.log_ratio >= self.threshold

    def supported_kappas(self) -> list[float]:
        """The tried modulations whose log ratio reaches the threshold."""
        return [kappa for kappa, value in self.log_ratios.items() if value >= self.threshold]

    def reason(self) -> str:
        supported = ", ".join(f"{kappa:g}" for kappa in self.supported_kappas()) or "none"
        return (
            f"the phase sums of the {self.shaft}'s first sidebands around the mesh harmonics "
            f"({self.n_sums} harmonic x channel x run) are {self.log_ratio:.0f} nats more likely, without "
            f"the run that favours it most ({self.total:.0f} with it), with an eccentric {self.shaft} shaft "
            f"({1e6 * self.run_out:.3g} um run-out, mesh stiffness modulation {self.kappa:g}) than with the "
            f"gears' pitch errors alone (threshold {self.threshold:g}; modulations tried that reach it: "
            f"{supported}): a modulation pitch errors do not make"
        )

    def summary(self) -> dict[str, Any]:
        """JSON-ready."""
        return {
            "shaft": self.shaft,
            "run_out_m": self.run_out,
            "kappa": self.kappa,
            "log_ratio": self.log_ratio,
            "log_ratio_all_runs": self.total,
            "log_ratios": {f"{kappa:g}": value for kappa, value in self.log_ratios.items()},
            "n_sums": self.n_sums,
            "threshold": self.threshold,
            "named": self.decisive,
            "seconds": self.seconds,
        }


def sideband_triples(names: Sequence[str], shaft: str) -> list[tuple[int, int, int]]:
    """(carrier, upper, lower) positions in ``names`` of each mesh harmonic's first ``shaft`` sidebands."""
    position = {name: index for index, name in enumerate(names)}
    triples: list[tuple[int, int, int]] = []
    for harmonic in _HARMONICS:
        carrier, upper, lower = f"mesh{harmonic}", f"mesh{harmonic}_sb_{shaft}+1", f"mesh{harmonic}_sb_{shaft}-1"
        if all(name in position for name in (carrier, upper, lower)):
            triples.append((position[carrier], position[upper], position[lower]))
    return triples


def phase_sums(phasors: np.ndarray, triples: Sequence[tuple[int, int, int]]) -> np.ndarray:
    """Q = arg P(upper) + arg P(lower) - 2 arg P(carrier), wrapped to (-pi, pi], per triple on the last axis."""
    angles = np.angle(phasors)
    sums = np.stack(
        [angles[..., upper] + angles[..., lower] - 2.0 * angles[..., carrier] for carrier, upper, lower in triples],
        axis=-1,
    )
    return np.angle(np.exp(1j * sums))


def _concentration(resultant: np.ndarray) -> np.ndarray:
    """Von Mises concentration of a mean resultant length (Best and Fisher's approximation)."""
    r = np.clip(resultant, 1e-6, 0.999)
    return np.where(
        r < 0.53,
        2 * r + r**3 + 5 * r**5 / 6,
        np.where(r < 0.85, -0.4 + 1.39 * r + 0.43 / (1 - r), 1 / (r**3 - 4 * r**2 + 3 * r)),
    )


def log_density(observed: np.ndarray, drawn: np.ndarray, noise_variance: np.ndarray) -> np.ndarray:
    """Von Mises log density of each observed phase sum under the drawn ones (first axis), widened by its noise.

    The drawn sums give the mean direction and a concentration; the
    observed sum's own noise variance (rad^2) is added to the
    concentration's inverse (the wrapped-normal match).
    """
    resultant = np.exp(1j * drawn).mean(axis=0)
    concentration = 1.0 / (1.0 / _concentration(np.abs(resultant)) + noise_variance)
    return (
        concentration * np.cos(observed - np.angle(resultant))
        - np.log(2.0 * math.pi * scipy.special.i0e(concentration))
        - concentration
    )


def _spread_vectors(base: FitResult) -> list[np.ndarray]:
    """The fit's optimiser vector and, for each :data:`PARAMETER_SPREAD` parameter, one step up and one down."""
    problem, values = base.problem, base.values
    positions = base.positions
    vectors = [base.vector]
    for name, factor in PARAMETER_SPREAD.items():
        for scale in (factor, 1.0 / factor):
            vectors.append(problem.vector({**values, name: values[name] * scale}, positions))
    return vectors


def shafts_tested(case: RigCase, *, min_orders: float = DEFAULT_SETTINGS.phases.min_sideband_orders) -> list[str]:
    """The shafts whose first sidebands lie at least ``min_orders`` pinion orders from their carrier."""
    pinion_orders = {"pinion": 1.0, "gear": case.design.z1 / case.design.z2}
    return [shaft for shaft, orders in pinion_orders.items() if orders >= min_orders]


def modulation_evidence(
    case: RigCase,
    base: FitResult,
    shaft: str,
    run_out: float,
    *,
    kappas: Sequence[float] = DEFAULT_SETTINGS.phases.modulation_kappas,
    threshold: float = DEFAULT_SETTINGS.phases.phase_evidence_threshold,
    draws_per_point: int = DEFAULT_SETTINGS.phases.phase_draws_per_point,
) -> ModulationEvidence:
    """Score the rig's sideband phase sums of ``shaft`` with and without an eccentric shaft.

    Parameters
    ----------
    case : RigCase
        A case with the pitch-error allowance applied (its drawn errors are the H0 draws).
    base : FitResult
        The model the diagnosis ends with (its named effects included).
    shaft : str
        "pinion" or "gear".
    run_out : float
        Eccentricity amplitude of the hypothesis, m.
    kappas : sequence of float
        Mesh stiffness modulations tried.
    threshold : float
        Log ratio that names the eccentricity, nats.
    draws_per_point : int
        Pitch-error draws at each point of the parameter spread.

    Returns
    -------
    ModulationEvidence
    """
    clock = time.perf_counter()
    allowance = case.pitch_allowance
    drawn_errors = [] if allowance is None else list(allowance.drawn_errors)[:draws_per_point]
    line = np.array(case.layout.kinds) == "line"
    line_columns = np.array(case.layout.columns)[line]
    names = [name for name, kind in zip(case.layout.names, case.layout.kinds) if kind == "line"]
    triples = sideband_triples(names, shaft)
    if not drawn_errors or not triples:
        return ModulationEvidence.from_sums(
            shaft, run_out, {kappa: np.zeros((case.n_op, 1)) for kappa in kappas}, 0, threshold=threshold
        )
    rig_phasors = np.zeros((case.n_op, len(case.channels), len(names)), dtype=complex)
    for op in range(case.n_op):
        for index, channel in enumerate(case.channels):
            record = np.asarray(case.rig[channel].values[op], dtype=float)
            rig_phasors[op, index] = case.processors[op].model_line_phasors(record[None])[0][line_columns]
    sigma = case.line_noise_sigma()[..., line]
    observed = phase_sums(rig_phasors, triples)
    # a phase's noise variance is (sigma / |P|)^2 per quadrature; the carrier's counts twice over
    noise_variance = np.stack(
        [
            (sigma[..., upper] / np.abs(rig_phasors[..., upper])) ** 2
            + (sigma[..., lower] / np.abs(rig_phasors[..., lower])) ** 2
            + 4.0 * (sigma[..., carrier] / np.abs(rig_phasors[..., carrier])) ** 2
            for carrier, upper, lower in triples
        ],
        axis=-1,
    )
    usable = np.isfinite(observed) & np.isfinite(noise_variance) & case.usable[..., None]
    hypotheses: list[tuple[Eccentricity, ...]] = [()]
    hypotheses += [
        (Eccentricity({"amplitude": run_out, "phase": 0.0, "kappa": float(kappa), "shaft": shaft}),) for kappa in kappas
    ]
    clean = [
        [
            replace(base.problem.run_task(vector, op), periodicity="free", reduction="line_phasors")
            for op in range(case.n_op)
        ]
        for vector in _spread_vectors(base)
    ]
    tasks = [
        replace(task, effects=(*task.effects, *extra), pitch_errors=errors)
        for extra in hypotheses
        for runs in clean
        for errors in drawn_errors
        for task in runs
    ]
    values = np.stack([value for value, _ in case.execute(tasks)])[..., line_columns]
    values = values.reshape(len(hypotheses), len(clean) * len(drawn_errors), case.n_op, len(case.channels), len(names))
    scored = [
        np.where(
            usable,
            log_density(
                np.nan_to_num(observed), phase_sums(values[index], triples), np.nan_to_num(noise_variance, nan=1e6)
            ),
            0.0,
        )
        for index in range(len(hypotheses))
    ]
    per_sum = {float(kappa): scored[index + 1] - scored[0] for index, kappa in enumerate(kappas)}
    return ModulationEvidence.from_sums(
        shaft, run_out, per_sum, int(usable.sum()), threshold=threshold, seconds=time.perf_counter() - clock
    )


def fit_modulated_run_out(
    case: RigCase,
    base: FitResult,
    base_held: HeldOut,
    evidence: ModulationEvidence,
    rng: np.random.Generator,
    *,
    family: EffectFamily | None = None,
    settings: DiagnosisSettings = DEFAULT_SETTINGS,
) -> CandidateScore:
    """The run-out the phase sums name, fitted on top of the base and scored on held-out runs.

    ``family`` is the effect the run-out is named as (its
    :attr:`~uqgear.diagnosis.effects.EffectFamily.run_out` hook says which
    parameters hold the run-out, its phase, shaft and modulation; default:
    the first registered family with one, eccentricity). Its modulation is
    held at the one the phase sums favour (the compared amplitudes cannot
    see it: the fit would trade it for the run-out); its run-out and phase
    are fitted from the run-out the lines read, only the new effect's
    parameters free (a screening fit), and its held-out gap against the
    base's gives its share of the shrink.
    """
    family = family or run_out_family()
    if family is None or family.run_out is None:
        raise DiagnosisError("fit_modulated_run_out: no registered effect family reads as a shaft run-out")
    spec = family.run_out
    library = next(
        candidate
        for candidate in family.variants(case.design, {})
        if family.run_out_shaft(dict(candidate.choices)) == evidence.shaft
    )
    modulation = family.parameter_name(spec.modulation)
    fitted = tuple(parameter for parameter in library.fitted if parameter.name != modulation)
    starts = tuple(
        {family.parameter_name(spec.amplitude): evidence.run_out, family.parameter_name(spec.phase): phase}
        for phase in (0.5 * math.pi, 1.5 * math.pi)
    )
    candidate = replace(
        library, choices=(*library.choices, (spec.modulation, evidence.kappa)), fitted=fitted, starts=starts
    )
    result = fit_candidate(case, candidate, base, full=False, max_evaluations=settings.screening.screening_evaluations)
    entry = score_candidate(
        result, leave_one_out(result), base_held, "screening", rng, n_resamples=settings.verdict.bootstrap_resamples
    )
    return replace(entry, effect_gain=base.cost - result.cost)


__all__ = [
    "PARAMETER_SPREAD",
    "ModulationEvidence",
    "sideband_triples",
    "phase_sums",
    "log_density",
    "shafts_tested",
    "modulation_evidence",
    "fit_modulated_run_out",
]
