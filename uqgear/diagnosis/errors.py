"""The diagnosis's error: an input of the diagnosis or the blind test that is not valid."""

from __future__ import annotations

from ..common.errors import UqgearError


class DiagnosisError(UqgearError):
    """A diagnosis or blind-test input is not valid (unknown effect, bad option)."""
