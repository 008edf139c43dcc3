"""Self-contained HTML reports of study results.

:func:`write_report` reads the ``<analysis>.nc`` files of a run folder (and
nothing else) and writes ``report.html``: one file, figures embedded as
base64 PNG, no script, style sheet or font fetched from the network. It holds

* first, "What this shows": the few statements a gear designer acts on
  (worst dynamic load and where, where the teeth separate at each end of
  the T2 interval, back-side contact, regime windows, the largest Sobol
  drivers), each computed from the result Datasets by
  :mod:`~uqgear.report.headline`;
* all findings and caveats collected;
* one section per analysis with its figures (envelope bands, bifurcation
  diagrams with their envelopes, regime maps, time history / phase plane /
  Poincare map / spectrum panels, Sobol bars with confidence intervals,
  polynomial-chaos validation), the findings computed from the data and the
  caveats (surrogate error, non-smooth regions, distributions assumed);
* last, collapsed (``<details>``), the provenance: study summary, design
  table, uncertain parameters, seed, package versions, run time and the
  study definition.

Figures are drawn with matplotlib's Agg canvas (no pyplot, no display);
colour maps are perceptually uniform (cividis, viridis), so they read in
grey, and curves differ by line style and marker too. Every axis names its
quantity and unit.

Each analysis type has one renderer, registered with
:func:`~uqgear.report.sections.renderer` in a module per family
(:mod:`~uqgear.report.dynamics_sections`, :mod:`~uqgear.report.uq_sections`,
:mod:`~uqgear.report.rig_sections`); a result of an unknown type still gets a
section listing its variables. This module lays out the page and reads and
writes the run folder.
"""

from __future__ import annotations

import html
from collections.abc import Sequence
from datetime import UTC, datetime
from pathlib import Path

import xarray as xr

from ..common.errors import UqgearError
from ..common.fileio import write_text_atomic
from ..uq.results import load_result

# imported for their renderers, which register themselves in RENDERERS
from . import continuation_sections, dynamics_sections, rating_sections, rig_sections, runup_sections, uq_sections  # noqa: F401
from .finding import HEADLINE_STYLE, headline_html
from .headline import headline_findings, headline_note
from .page import figure_html, html_page
from .presentation import display, format_value
from .sections import RENDERERS, Section, html_list, html_table, json_attr, section_from_attrs

REPORT_NAME = "report.html"


def _render_generic(ds: xr.Dataset, dpi: int) -> Section:
    section = section_from_attrs(ds)
    rows = "".join(
        f"<tr><td>{html.escape(str(name))}</td><td>{html.escape(str(dict(ds[name].sizes)))}</td>"
        f"<td>{html.escape(str(ds[name].attrs.get('units', '')))}</td></tr>"
        for name in ds.data_vars
    )
    section.tables.append(f"<table><tr><th>variable</th><th>dims</th><th>units</th></tr>{rows}</table>")
    return section


_STYLE = (
    """
body { font-family: sans-serif; max-width: 1100px; margin: 2em auto; padding: 0 1em; color: #111; }
h1 { font-size: 1.6em; } h2 { font-size: 1.3em; border-bottom: 1px solid #999; margin-top: 2em; }
h3 { font-size: 1.1em; }
table { border-collapse: collapse; margin: 0.5em 0; font-size: 0.9em; }
td, th { border: 1px solid #bbb; padding: 2px 8px; text-align: left; vertical-align: top; }
th { background: #eee; }
figure { margin: 1em 0; } figure img { max-width: 100%; border: 1px solid #ddd; }
figcaption { font-size: 0.9em; color: #333; }
.caveats li { color: #6b3a00; }
pre { background: #f4f4f4; padding: 0.5em; overflow-x: auto; font-size: 0.85em; }
details#provenance { margin-top: 2.5em; border-top: 1px solid #999; padding-top: 0.5em; }
details#provenance > summary { font-size: 1.2em; font-weight: bold; cursor: pointer; }
"""
    + HEADLINE_STYLE
)


def _design_rows(ds: xr.Dataset) -> list[tuple[str, str]]:
    design = json_attr(ds, "design", {})
    units = {
        "module": "m",
        "pressure_angle": "deg",
        "face_width": "m",
        "youngs_modulus": "Pa",
        "m1": "kg",
        "m2": "kg",
        "I1": "kg m²",
        "I2": "kg m²",
        "k1": "N/m",
        "k2": "N/m",
        "backlash": "m (total, 2b)",
        "ste_amplitude": "m",
        "z1": "teeth",
        "z2": "teeth",
    }
    return [
        (key, f"{value:.6g} {units.get(key, '')}".strip() if isinstance(value, (int, float)) else str(value))
        for key, value in design.items()
    ]


def _design_notes(ds: xr.Dataset) -> list[str]:
    """What the model did with the design's geometry (an undercut tooth is modelled, with a warning)."""
    from types import SimpleNamespace

    from ..physics.geometry import geometry_notes

    values = json_attr(ds, "design", {})
    try:
        return geometry_notes(SimpleNamespace(**values))
    except (TypeError, ValueError, AttributeError, ArithmeticError):
        return []  # a result without a complete design: nothing to say about its geometry


def _uncertain_rows(ds: xr.Dataset) -> list[tuple[str, str]]:
    rows = []
    for name, entry in json_attr(ds, "uncertain_parameters", {}).items():
        if entry.get("kind") == "interval":
            text = f"interval [{format_value(name, entry['lower'])}, {format_value(name, entry['upper'])}]"
        else:
            parameters = ", ".join(f"{k}={v:.6g}" for k, v in entry.get("parameters", {}).items())
            text = f"{entry.get('distribution')}({parameters}) [{display(name)[1]}]"
        if entry.get("source") and entry.get("source") != "given":
            text += f"; {entry['source']}"
        rows.append((name, text))
    return rows


def _summary_rows(results: Sequence[xr.Dataset], sections: Sequence[Section]) -> list[tuple[str, str]]:
    """The study summary table: study, design, seed, analyses, runs and times."""
    first = results[0]
    total_time = sum(float(ds.attrs.get("run_time_s", 0.0)) for ds in results)
    total_runs = sum(int(ds.attrs.get("model_runs", 0)) for ds in results)
    return [
        ("study", str(first.attrs.get("study_name", "study"))),
        ("description", str(first.attrs.get("study_description", ""))),
        ("study file", str(first.attrs.get("study_path", ""))),
        ("design", f"{first.attrs.get('design_name', '')} (from {first.attrs.get('design_source', '')})"),
        (
            "design overrides",
            ", ".join(f"{k} = {v}" for k, v in json_attr(first, "design_overrides", {}).items()) or "none",
        ),
        ("seed", str(first.attrs.get("study_seed", first.attrs.get("seed", "")))),
        (
            "seed spawn key per analysis",
            ", ".join(
                f"{ds.attrs.get('analysis_name', '?')} {ds.attrs['seed_spawn_key']}"
                for ds in results
                if "seed_spawn_key" in ds.attrs
            )
            or "none recorded",
        ),
        ("analyses", ", ".join(f"{s.name} ({s.kind})" for s in sections)),
        ("model runs", str(total_runs)),
        ("run time", f"{total_time:.1f} s (sum over analyses)"),
        ("results created", str(first.attrs.get("created", ""))),
        ("report created", datetime.now(UTC).isoformat(timespec="seconds")),
    ]


def _section_html(section: Section) -> list[str]:
    """The parts of one analysis's section: facts, figures, tables, findings and caveats."""
    parts = [
        f'<section class="analysis" id="analysis-{html.escape(section.name)}" data-type="{html.escape(section.kind)}">',
        f"<h2>{html.escape(section.title)}</h2>",
    ]
    if section.description:
        parts.append(f"<p>{html.escape(section.description)}</p>")
    if section.facts:
        parts.append(html_table(section.facts))
    for figure in section.figures:
        parts.append(figure_html(figure.png, figure.caption))
    parts.extend(section.tables)
    parts.append("<h3>Findings</h3>" + html_list(section.findings))
    parts.append("<h3>Caveats</h3>" + html_list(section.caveats, "caveats"))
    parts.append("</section>")
    return parts


def build_report(results: Sequence[xr.Dataset], *, dpi: int = 110) -> str:
    """The HTML text of a report on the results of one run.

    Parameters
    ----------
    results : sequence of xarray.Dataset
        Analysis results as written by :func:`uqgear.study.running.run_analyses`
        (with their provenance attributes), in analysis order.
    dpi : int
        Figure resolution.

    Returns
    -------
    str
        One self-contained HTML document.
    """
    if not results:
        raise UqgearError("report: expected at least one analysis result; got none")
    first = results[0]
    sections = []
    for ds in results:
        kind = str(ds.attrs.get("analysis_type", ""))
        sections.append(RENDERERS.get(kind, _render_generic)(ds, dpi))
    study_name = str(first.attrs.get("study_name", "study"))
    versions = json_attr(first, "provenance_versions", {})
    if "numba_target_cpu" in first.attrs:
        versions["kernels compiled for (CPU)"] = str(first.attrs["numba_target_cpu"])
    summary = _summary_rows(results, sections)
    parts = [
        f"<h1>uqgear report: {html.escape(study_name)}</h1>",
        headline_html(headline_findings(results), headline_note(results)),
        '<section id="findings"><h2>Findings</h2>',
    ]
    for section in sections:
        if section.findings:
            parts.append(f"<h3>{html.escape(section.title)}</h3>" + html_list(section.findings))
    parts.append("</section>")
    parts.append('<section id="caveats"><h2>Caveats</h2>')
    caveats = [f"design: {note}" for note in _design_notes(first)]
    caveats += [f"{section.name}: {caveat}" for section in sections for caveat in section.caveats]
    parts.append(html_list(caveats, "caveats"))
    parts.append("</section>")
    for section in sections:
        parts.extend(_section_html(section))
    # provenance last and collapsed: what was run, with what, by which versions and seeds
    parts += [
        '<details id="provenance"><summary>Provenance: study, design, parameters, versions, seeds</summary>',
        '<section id="summary"><h2>Study summary</h2>',
        html_table(summary, table_id="summary-table"),
        '<h3 id="design">Design</h3>',
        html_table(_design_rows(first), ("key", "value"), "design-table"),
        '<h3 id="uncertain">Uncertain parameters</h3>',
        html_table(_uncertain_rows(first), ("parameter", "definition"), "uncertain-table")
        if _uncertain_rows(first)
        else "<p>None.</p>",
        '<h3 id="versions">Versions</h3>',
        html_table(sorted(versions.items()), ("package", "version"), "versions-table"),
        "</section>",
    ]
    study_text = str(first.attrs.get("study", ""))
    if study_text:
        parts.append(
            f'<section id="study-text"><h2>Study definition</h2><pre>{html.escape(study_text)}</pre></section>'
        )
    parts.append("</details>")
    return html_page(f"uqgear report: {study_name}", _STYLE, parts)


def load_results(directory: str | Path) -> list[xr.Dataset]:
    """The analysis results (``*.nc``) of a run folder, in analysis order.

    Raises
    ------
    UqgearError
        If the folder does not exist or holds no result files.
    """
    folder = Path(directory)
    if not folder.is_dir():
        raise UqgearError(f"{folder}: no such folder; expected the output folder of 'uqgear run'")
    paths = sorted(path for path in folder.glob("*.nc") if not path.name.startswith("."))
    if not paths:
        raise UqgearError(f"{folder}: no result files (*.nc); expected the output folder of 'uqgear run'")
    results = [load_result(path) for path in paths]
    for path, ds in zip(paths, results):
        if "analysis_type" not in ds.attrs:
            raise UqgearError(f"{path}: not an analysis result of 'uqgear run' (no analysis_type attribute)")
    return sorted(results, key=lambda ds: int(ds.attrs.get("analysis_index", 0)))


def write_report(directory: str | Path, *, dpi: int = 110) -> Path:
    """Build ``<directory>/report.html`` from the result files in the folder (written atomically).

    Parameters
    ----------
    directory : str or Path
        A folder of result files (``uqgear run`` or :func:`uqgear.run_study`).
    dpi : int
        The figures' resolution.

    Returns
    -------
    pathlib.Path
        The report written.

    Examples
    --------
    >>> import tempfile
    >>> import uqgear
    >>> study = uqgear.parse_study('''
    ... name: one_run
    ... design: {name: locomotive}
    ... operating_points: {pinion_speed: 2000, drive_torque: 7000, adhesion_torque: 33000}
    ... simulation: {n_periods: 60, keep_periods: 20}
    ... analyses:
    ...   - {type: simulate, name: run, samples_per_period: 16}
    ... ''')
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     _ = uqgear.run_study(study, folder, show_progress=False)
    ...     report = uqgear.write_report(folder, dpi=60)
    ...     html = report.read_text()
    >>> report.name, html.startswith("<!DOCTYPE html>"), "<title>uqgear report: one_run</title>" in html
    ('report.html', True, True)
    """
    folder = Path(directory)
    text = build_report(load_results(folder), dpi=dpi)
    target = folder / REPORT_NAME
    write_text_atomic(target, text)
    return target


__all__ = ["build_report", "write_report", "load_results", "REPORT_NAME"]
