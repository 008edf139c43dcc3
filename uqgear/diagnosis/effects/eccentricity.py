"""Eccentricity (shaft run-out): a once-per-revolution displacement in the TE and a modulated mesh stiffness."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from ...physics.design import Design
from ...physics.effects import Eccentricity
from ..candidates import Candidate
from .base import START_PHASES, EffectFamily, RunOut


def _sideband_modulation(observed: Mapping[str, np.ndarray], shaft: str) -> float | None:
    """The mesh stiffness modulation at a shaft's order the accelerometers show, or None (no accelerometer).

    A modulation of relative depth ``kappa`` puts two sidebands of about
    ``kappa / 2`` of the mesh line each at the shaft's order: their sum over
    the mesh line, median over runs and accelerometers.
    """
    ratios = []
    for key, mesh in observed.items():
        channel, _, feature = key.partition(":")
        if feature != "mesh1" or channel == "te":
            continue
        upper = observed.get(f"{channel}:mesh1_sb_{shaft}+1")
        lower = observed.get(f"{channel}:mesh1_sb_{shaft}-1")
        if upper is None or lower is None:
            continue
        with np.errstate(divide="ignore", invalid="ignore"):
            ratio = (upper + lower) / mesh
        ratios.extend(ratio[np.isfinite(ratio) & (mesh > 0)].tolist())
    return float(np.median(ratios)) if ratios else None


#: Shares of the housings' sideband reading the modulation starts at too (the reading over-reads a weak
#: run-out's modulation: noise and speed wander add to the sidebands, never take from them).
SIDEBAND_SHARES: tuple[float, float] = (0.1, 1.0 / 3.0)


class EccentricityFamily(EffectFamily):
    """A run-out of the pinion or the gear shaft (docs/model/unmodelled-effects.md section 6).

    Variants: one per shaft, its run-out, phase and mesh-stiffness
    modulation fitted. The run-out starts at the median first-order shaft
    line of the TE (the run-out enters the TE directly), the modulation at
    none and at what the public eccentricity campaign shows per metre of
    run-out (0.03 at 12 um). Its response repeats over its shaft's revolution.
    Hint order: the TE first, where the run-out enters directly (its
    median first-order shaft line); only a campaign without a TE reads the
    accelerometers, whose once-per-revolution line is a housing's
    acceleration that says nothing of the run-out by itself: there the
    run-out starts at the stiffness modulation its shaft's sidebands of the
    mesh line show (their sum over the mesh line, median over runs and
    accelerometers) divided by the modulation per metre of run-out, and
    the modulation at none, at that reading and at :data:`SIDEBAND_SHARES`
    of it: the sidebands hold the noise's and a wandering speed's share
    too (the virtual rig's campaigns without encoders read 4e-4 to 2e-3
    on a shaft without a run-out, a weak run-out's own modulation), so a
    weak run-out's modulation may lie well below its reading.

    Its fits read as a shaft run-out (:attr:`run_out`): the rules that tell a
    run-out from the gears' own pitch errors apply to it, its modulation being
    what pitch errors do not make. The change scoring tries the modulation in
    proportion to the run-out (:attr:`proportional`).
    """

    name = "eccentricity"
    physics = Eccentricity
    strength = "amplitude"
    # the weak level sits near the detection limit of the public campaigns' noise, the strong one at their own
    ladder = (3e-8, 3e-7, 12e-6)
    run_out = RunOut(amplitude="amplitude", phase="phase", shaft="shaft", modulation="kappa")
    # a run-out modulates the mesh stiffness with it (the public eccentricity campaign: kappa 0.03 at 12 um)
    proportional = {"kappa": 2500.0}

    def look_alike(self, channel: str) -> str:
        """On the TE alone an encoder's mounting run-out reads as a shaft's: a line once per revolution of its shaft."""
        if channel == "te":
            return "an encoder's mounting run-out (once per revolution of its shaft, as a shaft's run-out)"
        return ""

    def separated_by(self) -> tuple[str, ...]:
        """Records at a higher speed: the housings' response to a run-out grows steeply with the shaft speed.

        The model's once-per-revolution acceleration of both housings grows
        sixteen-fold per doubling of the speed and not with the load, while an
        encoder's run-out stays in the TE.
        """
        return (
            "records at a higher speed: the bearing housings' response to a shaft's run-out grows steeply with "
            "the shaft speed (about sixteen-fold per doubling in the model) until the accelerometers see it, "
            "while an encoder's run-out leaves them still",
        )

    def variants(self, design: Design, hints: Mapping[str, float]) -> list[Candidate]:
        fitted = (
            self.strength_parameter("amplitude", 1e-6, upper=1e-4),
            self.parameter("phase", 1.0, 0.0, 2.0 * np.pi),
            self.strength_parameter("kappa", 1e-3, upper=0.3),
        )
        variants = []
        for shaft in ("pinion", "gear"):
            amplitude = float(np.clip(hints.get(f"eccentricity_{shaft}", 5e-6), 1e-9, 5e-5))
            # no modulation, or as much as the public campaign per metre of run-out (0.03 at 12 um)
            kappa = min(self.proportional["kappa"] * amplitude, 0.1)
            kappas = [1e-9, kappa]
            if hints.get(f"eccentricity_{shaft}_sidebands"):
                # read off the housings' sidebands, an upper reading: a share of it too
                kappas[1:1] = [share * kappa for share in SIDEBAND_SHARES]
            starts = self.grid(amplitude=(amplitude,), phase=START_PHASES, kappa=kappas)
            variants.append(self.candidate(f"eccentricity[{shaft}]", (("shaft", shaft),), fitted, starts, shaft))
        return variants

    def hints(self, observed: Mapping[str, np.ndarray], locked_lines: Sequence[Mapping[str, Any]]) -> dict[str, float]:
        """The run-out of each shaft, m: the TE's median first-order shaft line, else the accelerometers' sidebands.

        A run-out read off the sidebands is marked by
        ``eccentricity_SHAFT_sidebands`` (1.0): its modulation then starts at
        shares of the reading too (:meth:`variants`).

        Examples
        --------
        >>> from uqgear.diagnosis.effects import effect_family
        >>> family = effect_family("eccentricity")
        >>> family.hints({"te:shaft_pinion1": np.array([2e-6, 3e-6, 4e-6])}, [])
        {'eccentricity_pinion': 3e-06}
        >>> housing = {"acc_gear:mesh1": np.array([10.0]), "acc_gear:mesh1_sb_gear+1": np.array([0.02]),
        ...            "acc_gear:mesh1_sb_gear-1": np.array([0.03])}
        >>> read = family.hints(housing, [])
        >>> round(read["eccentricity_gear"], 9), read["eccentricity_gear_sidebands"]  # modulation 0.005, 2500 per m
        (2e-06, 1.0)
        """
        hints = {}
        te = any(key.startswith("te:") for key in observed)
        for shaft in ("pinion", "gear"):
            values = observed.get(f"te:shaft_{shaft}1")
            if values is not None:
                values = values[np.isfinite(values)]
                if values.size:
                    hints[f"eccentricity_{shaft}"] = float(np.median(values))
            elif not te:
                modulation = _sideband_modulation(observed, shaft)
                if modulation is not None:
                    hints[f"eccentricity_{shaft}"] = modulation / self.proportional["kappa"]
                    hints[f"eccentricity_{shaft}_sidebands"] = 1.0
        return hints

    def campaign_values(self, strength: float, phase: float, rng: np.random.Generator) -> dict[str, object]:
        # stiffness modulation in proportion (the public campaign: 12 um with kappa 0.03)
        return {
            self.strength: strength,
            "shaft": ("pinion", "gear")[int(rng.integers(2))],
            "phase": phase,
            "kappa": float(strength / 4e-4),
        }
