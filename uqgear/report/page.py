"""The page skeleton and the figure embedding shared by every HTML report.

A report is one self-contained file: figures are drawn on matplotlib's Agg
canvas outside pyplot (nothing to close, safe in threads) and embedded as
base64 PNG; no script, style sheet or font is fetched from the network.
"""

from __future__ import annotations

import base64
import html
import io
from collections.abc import Callable, Iterable, Sequence
from typing import Any, Literal

from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from ..common.forked import map_forked


def new_figure(
    width: float, height: float, *, layout: Literal["constrained", "compressed", "tight"] | None = "constrained"
) -> Figure:
    """A matplotlib Figure on an Agg canvas, outside pyplot; size in inches."""
    figure = Figure(figsize=(width, height), layout=layout)
    FigureCanvasAgg(figure)
    return figure


def figure_png(figure: Figure, dpi: int, *, tight: bool = False) -> bytes:
    """PNG bytes of a figure at ``dpi``; ``tight`` crops the canvas to what is drawn."""
    buffer = io.BytesIO()
    crop: dict[str, Any] = {"bbox_inches": "tight"} if tight else {}
    figure.savefig(buffer, format="png", dpi=dpi, **crop)
    return buffer.getvalue()


def figure_pngs(
    makers: Sequence[Callable[[], Figure]], dpi: int, *, tight: bool = False, processes: int = 2
) -> list[bytes]:
    """PNG bytes of the figures the ``makers`` draw, in order, drawn in up to ``processes`` forked processes.

    Laying out and rasterising a figure is single-threaded Python in
    matplotlib: a diagnosis report's three figures took 3.7 s of its 5 s
    one after the other. Each figure is drawn whole in one process
    (:func:`~uqgear.common.forked.map_forked`: closures over Datasets are
    inherited by fork rather than pickled), so the bytes are those of
    drawing it here. Without the ``fork`` start method, inside a daemonic
    process (which may not have children) or for a single figure they are
    drawn here.
    """
    makers = list(makers)
    # the dearest first is the caller's order to choose; one figure per task
    return map_forked(lambda index: figure_png(makers[index](), dpi, tight=tight), len(makers), processes)


def img_tag(png: bytes, alt: str) -> str:
    """An ``<img>`` element holding the PNG inline as base64."""
    encoded = base64.b64encode(png).decode("ascii")
    return f'<img alt="{html.escape(alt)}" src="data:image/png;base64,{encoded}">'


def figure_html(png: bytes, caption: str) -> str:
    """A ``<figure>`` of the PNG with its caption (also the image's alt text)."""
    return f"<figure>{img_tag(png, caption)}<figcaption>{html.escape(caption)}</figcaption></figure>"


def html_page(title: str, style: str, body: Iterable[str]) -> str:
    """A complete HTML document: ``title`` (escaped here), the report's own ``style`` rules and ``body`` parts.

    The parts are joined by newlines, as is the skeleton around them.
    """
    return "\n".join(
        [
            "<!DOCTYPE html>",
            '<html lang="en"><head><meta charset="utf-8">',
            f"<title>{html.escape(title)}</title>",
            f"<style>{style}</style></head><body>",
            *body,
            "</body></html>",
        ]
    )


__all__ = ["new_figure", "figure_png", "img_tag", "figure_html", "html_page"]
