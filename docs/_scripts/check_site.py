"""Check a built documentation site for missing images and dangling local links.

Usage: ``python docs/_scripts/check_site.py docs/_build/html``. Every ``<img src>``
and every local ``<a href>`` (no scheme, no ``mailto:``) of every page must point
at a file of the site, and a ``#fragment`` at an element with that ``id``. Exits
with status 1 and one line per problem otherwise.
"""

from __future__ import annotations

import sys
from html.parser import HTMLParser
from pathlib import Path
from urllib.parse import unquote, urlsplit


class _Page(HTMLParser):
    def __init__(self) -> None:
        super().__init__(convert_charrefs=True)
        self.targets: list[tuple[str, str]] = []
        self.ids: set[str] = set()

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        values = dict(attrs)
        if values.get("id"):
            self.ids.add(str(values["id"]))
        if tag == "img" and values.get("src"):
            self.targets.append(("image", str(values["src"])))
        elif tag == "a" and values.get("href"):
            self.targets.append(("link", str(values["href"])))


def _parse(path: Path) -> _Page:
    page = _Page()
    page.feed(path.read_text(encoding="utf-8", errors="replace"))
    return page


def problems(site: Path) -> list[str]:
    """Each missing image or dangling local link of the site, as one line."""
    pages = {path: _parse(path) for path in sorted(site.rglob("*.html"))}
    found = []
    for path, page in pages.items():
        for kind, target in page.targets:
            parts = urlsplit(target)
            if parts.scheme or target.startswith(("mailto:", "//", "javascript:")):
                continue
            if kind == "image" and target.startswith("data:"):
                continue
            destination = (path.parent / unquote(parts.path)).resolve() if parts.path else path
            if destination.is_dir():
                destination = destination / "index.html"
            if not destination.exists():
                found.append(f"{path.relative_to(site)}: {kind} {target!r} points at nothing")
                continue
            # viewcode's "[docs]" links on the highlighted-source pages name an object by where it is
            # defined, while the API documents a re-exported object under its public name: the page is
            # right and opens at its top, so only the page is checked there
            from_source = path.relative_to(site).parts[0] == "_modules"
            if parts.fragment and destination.suffix == ".html" and not from_source:
                ids = pages[destination].ids if destination in pages else _parse(destination).ids
                if unquote(parts.fragment) not in ids:
                    found.append(f"{path.relative_to(site)}: {kind} {target!r}: no element with that id")
    return found


def main() -> int:
    site = Path(sys.argv[1] if len(sys.argv) > 1 else "docs/_build/html")
    if not (site / "index.html").is_file():
        print(f"{site}: no built site (index.html missing)")
        return 1
    found = problems(site)
    for line in found:
        print(line)
    print(f"{len(list(site.rglob('*.html')))} pages checked, {len(found)} problems")
    return 1 if found else 0


if __name__ == "__main__":
    sys.exit(main())
