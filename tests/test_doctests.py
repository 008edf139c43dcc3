"""The ``Examples`` sections of the public names run and print what they say.

Every name in ``uqgear.__all__`` (``__version__`` aside: a string carries no
docstring of its own) documents itself with a numpydoc ``Examples`` section;
each section is run here as a doctest, one test per name, so an example that
drifts from the code fails with the runner's report of the first mismatch.
"""

from __future__ import annotations

import doctest
import inspect
import io
import os
import warnings

import pytest

import uqgear

#: Public names that are not documented objects (a plain string has no docstring of its own).
NOT_DOCUMENTED = {"__version__"}

PUBLIC = [name for name in uqgear.__all__ if name not in NOT_DOCUMENTED]

#: Floats printed in the examples are rounded on purpose; these flags only ease the layout.
OPTIONS = doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE


def _examples(name: str) -> list[doctest.DocTest]:
    """The doctests of one public name: its own docstring, without its methods' or members'."""
    obj = getattr(uqgear, name)
    finder = doctest.DocTestFinder(recurse=False)
    return [test for test in finder.find(obj, f"uqgear.{name}", globs={}) if test.examples]


def test_only_plain_values_go_undocumented():
    """A name is left out only when it is public and a plain value without a docstring of its own."""
    assert NOT_DOCUMENTED <= set(uqgear.__all__)
    assert all(isinstance(getattr(uqgear, name), str) for name in NOT_DOCUMENTED)


@pytest.mark.parametrize("name", PUBLIC)
def test_examples_run(name, tmp_path, monkeypatch):
    """The name's docstring has an ``Examples`` section, and its examples print what they show."""
    obj = getattr(uqgear, name)
    docstring = inspect.getdoc(obj) or ""
    assert "\nExamples\n--------\n" in f"\n{docstring}\n", f"uqgear.{name}: no numpydoc Examples section"
    tests = _examples(name)
    assert tests, f"uqgear.{name}: the Examples section holds no >>> example"
    # an example that wrote into the working directory would write here, and fail the check below
    monkeypatch.chdir(tmp_path)
    report = io.StringIO()
    runner = doctest.DocTestRunner(optionflags=OPTIONS)
    with warnings.catch_warnings():
        # an example shows a warning on purpose where it says so; others must not leak into the output
        warnings.simplefilter("ignore")
        for test in tests:
            runner.run(test, out=report.write)
    assert runner.failures == 0, (
        f"uqgear.{name}: {runner.failures} of {runner.tries} examples failed\n{report.getvalue()}"
    )
    assert runner.tries > 0, f"uqgear.{name}: every example is skipped"
    written = os.listdir(tmp_path)
    assert written == [], f"uqgear.{name}: the examples wrote {written} into the working directory"
