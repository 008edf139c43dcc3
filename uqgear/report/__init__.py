"""Self-contained HTML reports: studies, calibrations, diagnoses and blind tests.

Renderers take result Datasets and JSON summaries (never the objects that
made them), so calibration and diagnosis can write their reports without an
import circle.

May import :mod:`uqgear.common`, :mod:`uqgear.physics`, :mod:`uqgear.dynamics`
and :mod:`uqgear.uq`.
"""

from __future__ import annotations

from .study_report import build_report, write_report, load_results, REPORT_NAME
from .sections import renderer, RENDERERS
from .dynamics_sections import simulation_figure_png
from .findings import regime_findings, separation_findings
from .finding import Finding, headline_html
from .headline import headline_findings
from .calibration_report import write_calibration_report, calibration_report_html, calibration_findings
from .diagnosis_report import (
    diagnosis_report_html,
    diagnosis_findings,
    write_diagnosis_report,
    blindtest_report_html,
    write_blindtest_report,
)

__all__ = [
    "build_report",
    "write_report",
    "load_results",
    "simulation_figure_png",
    "renderer",
    "RENDERERS",
    "regime_findings",
    "REPORT_NAME",
    "write_calibration_report",
    "calibration_report_html",
    "diagnosis_report_html",
    "write_diagnosis_report",
    "blindtest_report_html",
    "write_blindtest_report",
    "separation_findings",
    "Finding",
    "headline_html",
    "headline_findings",
    "calibration_findings",
    "diagnosis_findings",
]
