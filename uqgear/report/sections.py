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


def _json_attr(ds: xr.Dataset | xr.DataArray, name: str, default: Any) -> Any:
    value = ds.attrs.get(name)
    if value is None:
        return default
    if isinstance(value, str):
        try:
            return json.loads(value)
        except ValueError:
            return default
    return value


def _section(ds: xr.Dataset) -> Section:
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
    settings = _json_attr(ds, "simulation_settings", {})
    if settings:
        section.facts.append(
            (
                "simulation",
                f"{settings.get('n_periods')} mesh periods, last "
                f"{settings.get('keep_periods')} kept" + (", Lyapunov exponent" if settings.get("lyapunov") else ""),
            )
        )
    points = _json_attr(ds, "operating_points", {})
    # the inputs actually held fixed (with the nominal values of uncertain parameters and defaults)
    fixed = _json_attr(ds, "fixed_inputs", None) or {
        key: value for key, value in points.items() if not isinstance(value, list)
    }
    if fixed:
        section.facts.append(
            ("fixed inputs", ", ".join(f"{short_name(k)} = {format_value(k, v)}" for k, v in fixed.items()))
        )
    return section


def _add_figure(section: Section, figure: Figure, caption: str, dpi: int) -> None:
    section.figures.append(ReportFigure(caption, figure_png(figure, dpi)))


def _table(rows: Sequence[tuple[str, str]], header: tuple[str, str] | None = None, table_id: str = "") -> str:
    head = f"<tr><th>{html.escape(header[0])}</th><th>{html.escape(header[1])}</th></tr>" if header else ""
    body = "".join(f"<tr><td>{html.escape(str(a))}</td><td>{html.escape(str(b))}</td></tr>" for a, b in rows)
    identifier = f' id="{table_id}"' if table_id else ""
    return f"<table{identifier}>{head}{body}</table>"


def _list(items: Sequence[str], css_class: str = "") -> str:
    if not items:
        return "<p>None.</p>"
    css = f' class="{css_class}"' if css_class else ""
    return f"<ul{css}>" + "".join(f"<li>{html.escape(item)}</li>" for item in items) + "</ul>"
