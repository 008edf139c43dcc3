"""How the study report shows quantities: labels, units and scale factors of variables and QoIs,
value formatting, and the line styles and markers that keep curves apart in grey."""

from __future__ import annotations

import numpy as np

# name -> (label, unit shown, factor from SI to the unit shown)
_DISPLAY: dict[str, tuple[str, str, float]] = {
    "pinion_speed": ("pinion speed $n_1$", "rpm", 1.0),
    "drive_torque": ("drive torque $T_1$", "kN m", 1e-3),
    "adhesion_torque": ("adhesion torque $T_2$", "kN m", 1e-3),
    "mesh_stiffness_scale": ("mesh stiffness scale", "-", 1.0),
    "k1": ("pinion bearing stiffness $k_1$", "GN/m", 1e-9),
    "k2": ("gear bearing stiffness $k_2$", "GN/m", 1e-9),
    "zeta_mesh": ("mesh damping ratio $\\zeta_m$", "-", 1.0),
    "zeta1": ("pinion bearing damping ratio $\\zeta_1$", "-", 1.0),
    "zeta2": ("gear bearing damping ratio $\\zeta_2$", "-", 1.0),
    "backlash": ("backlash $2b$", "µm", 1e6),
    "ste_amplitude": ("STE amplitude $e_r$", "µm", 1e6),
    "m1": ("pinion mass $m_1$", "kg", 1.0),
    "m2": ("gear mass $m_2$", "kg", 1.0),
    "I1": ("pinion inertia $I_1$", "kg m²", 1.0),
    "I2": ("gear inertia $I_2$", "kg m²", 1.0),
    "face_width": ("face width", "mm", 1e3),
    "dte_mean": ("mean DTE", "µm", 1e6),
    "dte_rms": ("RMS DTE", "µm", 1e6),
    "dte_peak_to_peak": ("peak-to-peak DTE", "µm", 1e6),
    "dynamic_load_factor": ("dynamic load factor (peak / run's F_T)", "-", 1.0),
    "peak_mesh_force": ("peak mesh force", "kN", 1e-3),
    "load_factor_rated": ("peak mesh force / rated mesh force", "-", 1.0),
    "acc_pinion_rms": ("RMS pinion acceleration", "m/s²", 1.0),
    "acc_gear_rms": ("RMS gear acceleration", "m/s²", 1.0),
    "fraction_drive_contact": ("time in drive-side contact", "%", 100.0),
    "fraction_separation": ("time with teeth apart", "%", 100.0),
    "fraction_back_contact": ("time in back-side contact", "%", 100.0),
    "largest_lyapunov": ("largest Lyapunov exponent", "1/s", 1.0),
    "root_stress_peak_pinion": ("pinion tooth root stress, peak", "MPa", 1e-6),
    "root_stress_peak_gear": ("gear tooth root stress, peak", "MPa", 1e-6),
    "root_stress_amplitude_pinion": ("pinion tooth root stress amplitude", "MPa", 1e-6),
    "root_stress_amplitude_gear": ("gear tooth root stress amplitude", "MPa", 1e-6),
    "contact_stress_peak_pinion": ("pinion flank contact stress, peak", "MPa", 1e-6),
    "contact_stress_peak_gear": ("gear flank contact stress, peak", "MPa", 1e-6),
    "contact_stress_amplitude_pinion": ("pinion flank contact stress amplitude", "MPa", 1e-6),
    "contact_stress_amplitude_gear": ("gear flank contact stress amplitude", "MPa", 1e-6),
}

# ---------------------------------------------------------------------------- regimes
# The regime vocabulary of uqgear.dynamics.regimes (REGIME_LABELS): period-n, then the
# non-periodic labels in the order legends list them.

#: Legend order of the labels other than period-n.
REGIME_ORDER: tuple[str, ...] = (
    "quasi_periodic_or_long_period",
    "quasi-periodic",
    "chaotic",
    "uncertain",
    "undetermined",
)
#: One-letter cell codes of the regime map (period-n shows n).
REGIME_CODES: dict[str, str] = {
    "quasi_periodic_or_long_period": "L",
    "quasi-periodic": "Q",
    "chaotic": "C",
    "uncertain": "U",
    "undetermined": "?",
}
#: Legend text of a regime label, where the label alone does not say it.
REGIME_LEGEND: dict[str, str] = {
    "quasi_periodic_or_long_period": "quasi-periodic or long period (repeats < 10 times)",
    "uncertain": "uncertain (Lyapunov exponent and 0-1 test disagree)",
    "undetermined": "undetermined (failed run)",
}
#: Colours kept out of the light-to-dark period-1 ... chaotic scale: labels that are no point on it.
REGIME_FIXED_COLOURS: dict[str, str] = {"uncertain": "#e07b7b", "undetermined": "#ffffff"}


def regime_legend(label: str) -> str:
    """Legend text of a regime label."""
    return REGIME_LEGEND.get(label, label)


_SHORT_NAMES = {
    "adhesion_torque": "T2",
    "drive_torque": "T1",
    "pinion_speed": "speed",
    "mesh_stiffness_scale": "mesh stiffness scale",
    "zeta_mesh": "mesh damping",
    "ste_amplitude": "STE amplitude",
    "k1": "pinion bearing stiffness",
    "k2": "gear bearing stiffness",
    "backlash": "backlash",
}
#: Line styles of the curves of one figure, in turn (told apart without colour).
LINE_STYLES = ("-", "--", "-.", ":", (0, (5, 1, 1, 1)), (0, (3, 1, 1, 1, 1, 1)))
#: Markers of the point sets of one figure, in turn.
MARKERS = ("o", "s", "^", "D", "v", "P", "X", "*", "<", ">")


def display(name: str) -> tuple[str, str, float]:
    """Axis label, unit and SI-to-unit factor of a variable or QoI."""
    if name in _DISPLAY:
        return _DISPLAY[name]
    return (name.replace("_", " "), "-", 1.0)


def axis_label(name: str) -> str:
    """``label [unit]`` for an axis."""
    label, unit, _ = display(name)
    return f"{label} [{unit}]"


def format_value(name: str, value: float) -> str:
    """A value in display units with its unit, e.g. ``38.2 kN m``."""
    _, unit, factor = display(name)
    if not np.isfinite(value):
        return "n/a"
    shown = f"{value * factor:.4g}"
    return shown if unit in ("-", "") else f"{shown} {unit}"


def short_name(name: str) -> str:
    return _SHORT_NAMES.get(name, name.replace("_", " "))
