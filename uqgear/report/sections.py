"""The study report's model: one :class:`Section` per analysis, the registry of section renderers,
and the helpers every renderer uses (section header facts, figures, tables, lists)."""

from __future__ import annotations

import html
import json
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import xarray as xr
from matplotlib.figure import Figure

from .page import figure_png
from .presentation import format_value, short_name


@dataclass
class ReportFigure:
    """One embedded figure."""

    caption: str
    png: bytes


@dataclass
class Section:
    """The part of the report belonging to one analysis."""

    name: str
    kind: str
    title: str
    description: str = ""
    figures: list[ReportFigure] = field(default_factory=list)
    findings: list[str] = field(default_factory=list)
    caveats: list[str] = field(default_factory=list)
    tables: list[str] = field(default_factory=list)
    facts: list[tuple[str, str]] = field(default_factory=list)


Renderer = Callable[[xr.Dataset, int], Section]
RENDERERS: dict[str, Renderer] = {}


def renderer(kind: str) -> Callable[[Renderer], Renderer]:
    """Decorator registering the report renderer of an analysis type."""

    def decorate(function: Renderer) -> Renderer:
        RENDERERS[kind] = function
        return function

    return decorate


def json_attr(ds: xr.Dataset | xr.DataArray, name: str, default: Any) -> Any:
    """The attribute ``name`` of ``ds`` decoded from JSON; ``default`` where it is absent or not valid JSON.

    An attribute that is not a string (a number written as such) is returned as it is.
    """
    value = ds.attrs.get(name)
    if value is None:
        return default
    if isinstance(value, str):
        try:
            return json.loads(value)
        except ValueError:
            return default
    return value


def section_from_attrs(ds: xr.Dataset) -> Section:
    """A :class:`Section` for the analysis result ``ds``, with the header facts its attributes give.

    Name, type and description of the analysis, and where present the model runs, the run time, the
    treatment of multi-valued responses, the simulation settings and the inputs held fixed; every renderer
    starts from it and adds its figures, findings and tables.
    """
    name = str(ds.attrs.get("analysis_name", "analysis"))
    kind = str(ds.attrs.get("analysis_type", "unknown"))
    section = Section(
        name=name,
        kind=kind,
        title=f"{name} ({kind.replace('_', ' ')})",
        description=str(ds.attrs.get("analysis_description", "")),
    )
    runs = ds.attrs.get("model_runs")
    if runs is not None:
        section.facts.append(("model runs", f"{int(runs)}"))
    seconds = ds.attrs.get("run_time_s")
    if seconds is not None:
        section.facts.append(("run time", f"{float(seconds):.1f} s"))
    treatment = ds.attrs.get("response_treatment")
    if treatment:
        section.facts.append(("multi-valued response", str(treatment)))
    settings = json_attr(ds, "simulation_settings", {})
    if settings:
        section.facts.append(
            (
                "simulation",
                f"{settings.get('n_periods')} mesh periods, last "
                f"{settings.get('keep_periods')} kept" + (", Lyapunov exponent" if settings.get("lyapunov") else ""),
            )
        )
    points = json_attr(ds, "operating_points", {})
    # the inputs actually held fixed (with the nominal values of uncertain parameters and defaults)
    fixed = json_attr(ds, "fixed_inputs", None) or {
        key: value for key, value in points.items() if not isinstance(value, list)
    }
    if fixed:
        section.facts.append(
            ("fixed inputs", ", ".join(f"{short_name(k)} = {format_value(k, v)}" for k, v in fixed.items()))
        )
    return section


def add_figure(section: Section, figure: Figure, caption: str, dpi: int) -> None:
    """Append ``figure``, rendered to PNG at ``dpi``, to ``section`` with its caption."""
    section.figures.append(ReportFigure(caption, figure_png(figure, dpi)))


def html_table(rows: Sequence[tuple[str, str]], header: tuple[str, str] | None = None, table_id: str = "") -> str:
    """A two-column HTML table of ``rows`` (text escaped), with an optional header row and ``id``."""
    head = f"<tr><th>{html.escape(header[0])}</th><th>{html.escape(header[1])}</th></tr>" if header else ""
    body = "".join(f"<tr><td>{html.escape(str(a))}</td><td>{html.escape(str(b))}</td></tr>" for a, b in rows)
    identifier = f' id="{table_id}"' if table_id else ""
    return f"<table{identifier}>{head}{body}</table>"


def html_list(items: Sequence[str], css_class: str = "") -> str:
    """An HTML bullet list of ``items`` (text escaped) with an optional CSS class; 'None.' where empty."""
    if not items:
        return "<p>None.</p>"
    css = f' class="{css_class}"' if css_class else ""
    return f"<ul{css}>" + "".join(f"<li>{html.escape(item)}</li>" for item in items) + "</ul>"
