"""Checks of the arguments a virtual-rig campaign takes, shared by the steady and the run-up rig.

:func:`uqgear.rig.virtual_rig.simulate_campaign` and
:func:`uqgear.rig.virtual_runup.simulate_runup_campaign` (and the foreign rig's
run-ups) take the same nuisances (speed wander, line interference, encoder
run-out), sampling rate and seed; each check turns one argument into the
form the acquisition chain uses, or raises an
:class:`~uqgear.common.errors.OperatingPointError` naming it.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

import numpy as np

from ..common.errors import OperatingPointError
from ..uq.seeds import as_seed_sequence


def check_speed_wander(speed_wander: Sequence[tuple[float, float]]) -> list[tuple[float, float]]:
    """The speed wander components of a campaign as ``(relative amplitude, frequency in Hz)`` pairs.

    Each component must give a relative amplitude in [0, 0.2) and a frequency above 0 Hz.

    Raises
    ------
    OperatingPointError
        A component is not a pair of numbers or lies outside those ranges, naming its index.

    Examples
    --------
    >>> from uqgear.rig.campaign_checks import check_speed_wander
    >>> check_speed_wander([(0.01, 0.5)])
    [(0.01, 0.5)]
    """
    components = []
    for index, component in enumerate(speed_wander):
        try:
            amplitude, frequency = (float(value) for value in component)
        except (TypeError, ValueError):
            raise OperatingPointError(f"speed_wander[{index}]: expected (relative amplitude, frequency in Hz); "
                                      f"got {component!r}") from None
        if not (math.isfinite(amplitude) and 0.0 <= amplitude < 0.2):
            raise OperatingPointError(f"speed_wander[{index}]: expected a relative amplitude in [0, 0.2); "
                                      f"got {amplitude!r}")
        if not (math.isfinite(frequency) and frequency > 0.0):
            raise OperatingPointError(f"speed_wander[{index}]: expected a frequency > 0 Hz; got {frequency!r}")
        components.append((amplitude, frequency))
    return components


def check_line_interference(line_interference: Mapping[float, float] | None, fs: float) -> dict[float, float]:
    """Mains-like lines on the accelerometers, frequency (Hz) -> amplitude (m s-2), checked against ``fs``.

    Frequencies must lie in (0, fs/2) and amplitudes be finite and >= 0; ``None`` gives no lines.

    Raises
    ------
    OperatingPointError
        A frequency or an amplitude outside those ranges.

    Examples
    --------
    >>> from uqgear.rig.campaign_checks import check_line_interference
    >>> check_line_interference({50: 0.1}, 20480.0)
    {50.0: 0.1}
    """
    lines = {}
    for frequency, amplitude in (line_interference or {}).items():
        if isinstance(frequency, bool) or not isinstance(frequency, (int, float)) or not 0 < frequency < fs / 2:
            raise OperatingPointError(f"line_interference: expected frequencies in (0, fs/2) Hz; got {frequency!r}")
        if isinstance(amplitude, bool) or not isinstance(amplitude, (int, float)) or not math.isfinite(amplitude) \
                or amplitude < 0:
            raise OperatingPointError(f"line_interference.{frequency:g}: expected an amplitude >= 0 m s-2; "
                                      f"got {amplitude!r}")
        lines[float(frequency)] = float(amplitude)
    return lines


def check_encoder_run_out(encoder_run_out: Mapping[str, float] | None) -> dict[str, float]:
    """Encoder mounting run-out per shaft (``pinion``, ``gear``) in m, each in [0, 1e-3).

    ``None`` gives no run-out.

    Raises
    ------
    OperatingPointError
        An unknown shaft or an amplitude outside that range.

    Examples
    --------
    >>> from uqgear.rig.campaign_checks import check_encoder_run_out
    >>> check_encoder_run_out({"pinion": 2e-6})
    {'pinion': 2e-06}
    """
    checked = {}
    for shaft, amplitude in (encoder_run_out or {}).items():
        if shaft not in ("pinion", "gear"):
            raise OperatingPointError(f"encoder_run_out: expected the shafts 'pinion' and/or 'gear'; got {shaft!r}")
        if isinstance(amplitude, bool) or not isinstance(amplitude, (int, float)) or not 0.0 <= amplitude < 1e-3:
            raise OperatingPointError(f"encoder_run_out.{shaft}: expected an amplitude in [0, 1e-3) m; "
                                      f"got {amplitude!r}")
        checked[shaft] = float(amplitude)
    return checked


def check_positive(name: str, value: object, lowest: float = 0.0) -> float:
    """``value`` as a float, which must be finite and above ``lowest``; ``name`` names it in the error.

    Raises
    ------
    OperatingPointError
        ``value`` is not a finite number above ``lowest``.

    Examples
    --------
    >>> from uqgear.rig.campaign_checks import check_positive
    >>> check_positive("fs", 20480)
    20480.0
    """
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)) \
            or not math.isfinite(float(value)) or float(value) <= lowest:
        raise OperatingPointError(f"{name}: expected a finite number > {lowest:g}; got {value!r}")
    return float(value)


def campaign_seed(seed: np.random.SeedSequence | int | None) -> np.random.SeedSequence:
    """The campaign's SeedSequence: ``seed`` as one, or fresh entropy where it is ``None``.

    Raises
    ------
    OperatingPointError
        ``seed`` is neither a SeedSequence, a non-negative integer nor ``None``.

    Examples
    --------
    >>> from uqgear.rig.campaign_checks import campaign_seed
    >>> campaign_seed(7).entropy
    7
    """
    return np.random.SeedSequence() if seed is None else as_seed_sequence(seed, error=OperatingPointError)


__all__ = ["check_speed_wander", "check_line_interference", "check_encoder_run_out", "check_positive", "campaign_seed"]
