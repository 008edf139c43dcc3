"""Self-contained HTML reports: studies, calibrations, diagnoses and blind tests.

Renderers take result Datasets and JSON summaries (never the objects that
made them), so calibration and diagnosis can write their reports without an
import circle.

May import :mod:`uqgear.common`, :mod:`uqgear.physics`, :mod:`uqgear.dynamics`
and :mod:`uqgear.uq`.
"""

from __future__ import annotations

from .calibration_report import calibration_findings, calibration_report_html, write_calibration_report
from .diagnosis_report import (
    blindtest_report_html,
    diagnosis_findings,
    diagnosis_report_html,
    write_blindtest_report,
    write_diagnosis_report,
)
from .dynamics_sections import simulation_figure_png
from .finding import Finding, headline_html
from .findings import regime_findings, separation_findings
from .headline import headline_findings
from .order_map_figures import order_map_figure, order_map_figure_png
from .sections import RENDERERS, renderer
from .study_report import REPORT_NAME, build_report, load_results, write_report

__all__ = [
    "build_report",
    "write_report",
    "load_results",
    "simulation_figure_png",
    "order_map_figure",
    "order_map_figure_png",
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
