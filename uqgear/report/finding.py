"""A headline finding: one sentence a designer acts on, with the numbers it rests on, and the
"What this shows" block that opens every report."""

from __future__ import annotations

import html
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

#: Element id of the block that opens every report.
HEADLINE_ID = "what-this-shows"

#: Rules of the block, added to a report's own style sheet.
HEADLINE_STYLE = """
#what-this-shows { background: #f4f7fb; border: 1px solid #9bb; padding: 0.3em 1em 0.5em 1em; margin: 1em 0; }
#what-this-shows h2 { margin-top: 0.4em; border: none; font-size: 1.25em; }
#what-this-shows li { margin: 0.3em 0; line-height: 1.35; }
#what-this-shows .note { color: #555; font-size: 0.85em; }
"""


@dataclass(frozen=True)
class Finding:
    """One headline statement.

    Attributes
    ----------
    text : str
        The sentence, as shown.
    facts : dict
        The numbers (in SI units, as stored in the results) and names the sentence rests on, so that a
        test can recompute them from the data.
    topic : str
        What the statement is about (``worst_load``, ``separation``, ``back_contact``, ``regimes``,
        ``sobol``, ``convergence``, ``verdict``, ...).
    """

    text: str
    facts: dict[str, Any] = field(default_factory=dict)
    topic: str = ""


def headline_html(findings: Sequence[Finding], note: str = "") -> str:
    """The ``<section id="what-this-shows">`` block: the findings as a list, then an optional note."""
    items = "".join(f"\n<li>{html.escape(finding.text)}</li>" for finding in findings)
    body = f"<ul>{items}\n</ul>" if items else "<p>No headline figures for these results; see the sections below.</p>"
    tail = f'\n<p class="note">{html.escape(note)}</p>' if note else ""
    return f'<section id="{HEADLINE_ID}"><h2>What this shows</h2>{body}{tail}\n</section>'


__all__ = ["Finding", "headline_html", "HEADLINE_ID", "HEADLINE_STYLE"]
