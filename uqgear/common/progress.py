"""Progress bars for long runs: rate and ETA in a terminal, silent elsewhere.

A bar is shown only when standard error is a terminal, so logs of batch jobs
and CI stay clean. The environment variable ``UQGEAR_PROGRESS`` overrides the
detection: ``0`` never shows a bar, ``1`` always does.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Iterable
from typing import TypeVar

from tqdm import tqdm

Item = TypeVar("Item")

#: Environment variable switching bars off (``0``) or forcing them on (``1``).
PROGRESS_ENVIRONMENT_VARIABLE = "UQGEAR_PROGRESS"


def progress_enabled() -> bool:
    """Whether bars are shown: ``UQGEAR_PROGRESS`` if set to 0/1, else whether stderr is a TTY."""
    setting = os.environ.get(PROGRESS_ENVIRONMENT_VARIABLE, "").strip()
    if setting == "0":
        return False
    if setting == "1":
        return True
    try:
        return sys.stderr.isatty()
    except (AttributeError, ValueError):
        # stderr replaced by an object without isatty, or closed
        return False


def progress(iterable_or_total: Iterable[Item] | int, *, desc: str, unit: str = "it", enabled: bool = True) -> tqdm:
    """A tqdm progress bar over an iterable, or over a count updated by hand.

    Parameters
    ----------
    iterable_or_total : iterable or int
        Items to iterate over (the bar wraps them), or the total count for a
        bar advanced with ``bar.update(n)``.
    desc : str
        Label in front of the bar.
    unit : str, default "it"
        Unit of the count shown with the rate ("sample" gives "sample/s").
    enabled : bool, default True
        False never shows the bar (a caller's ``progress=False``); True shows
        it when :func:`progress_enabled` says so.

    Returns
    -------
    tqdm.tqdm
        Usable as iterator and context manager; a disabled bar still iterates
        and accepts ``update`` calls, it just prints nothing.
    """
    disable = not enabled or not progress_enabled()
    if isinstance(iterable_or_total, bool) or not isinstance(iterable_or_total, (int, Iterable)):
        raise TypeError(f"progress: expected an iterable or an integer total; got {type(iterable_or_total).__name__}")
    if isinstance(iterable_or_total, int):
        return tqdm(total=iterable_or_total, desc=desc, unit=unit, disable=disable, dynamic_ncols=True)
    return tqdm(iterable_or_total, desc=desc, unit=unit, disable=disable, dynamic_ncols=True)


__all__ = ["progress", "progress_enabled", "PROGRESS_ENVIRONMENT_VARIABLE"]
