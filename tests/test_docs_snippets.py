"""The user guides' Python snippets run as written, each page's blocks in order in one script.

Code is read from the pages themselves, so a guide cannot drift from the API.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
# getting-started.md reads the main job's output; tests/test_readme.py runs that job
PAGES = sorted((ROOT / "docs" / "guides").glob("*.md"))
pytestmark = pytest.mark.slow


def _blocks(page: Path) -> list[str]:
    return re.findall(r"```python\n(.*?)```", page.read_text(), re.S)


def test_every_guide_is_checked():
    assert PAGES and all(page.exists() for page in PAGES)
    assert sum(len(_blocks(page)) for page in PAGES) >= 4


@pytest.mark.parametrize("page", [page for page in PAGES if _blocks(page)], ids=lambda page: page.stem)
def test_the_snippets_of_a_page_run(page, tmp_path):
    script = tmp_path / f"{page.stem}.py"
    script.write_text("\n\n".join(_blocks(page)))
    environment = {**os.environ, "MPLBACKEND": "Agg", "UQGEAR_PROGRESS": "0", "PYTHONPATH": str(ROOT)}
    completed = subprocess.run([sys.executable, str(script)], cwd=tmp_path, env=environment,
                               capture_output=True, text=True, timeout=900)
    assert completed.returncode == 0, f"{page.name}:\n{completed.stderr[-3000:]}"
