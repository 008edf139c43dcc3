"""Seeds: the one :class:`numpy.random.SeedSequence` all randomness comes from.

The caller gives a seed; its entropy is written to the ``seed_entropy``
attribute of every result so that a run can be repeated. Stages of an
analysis draw from children of it (:func:`child_seed`), so the same seed
gives the same numbers however often an analysis is run.
"""

from __future__ import annotations

import json

import numpy as np

from ..common.errors import ParameterSpaceError

#: A seed: a SeedSequence or an integer entropy for one.
SeedLike = np.random.SeedSequence | int


def as_seed_sequence(
    seed: SeedLike, *, setting: str = "seed", error: type[ValueError] | None = None
) -> np.random.SeedSequence:
    """Turn ``seed`` into a :class:`numpy.random.SeedSequence`.

    Parameters
    ----------
    seed : SeedSequence or int
        A seed sequence (used as is) or a non-negative integer entropy.
    setting : str
        Name of the setting, used in the error message.
    error : type, optional
        The error class to raise (the calling module's own; default
        :class:`ParameterSpaceError`).

    Returns
    -------
    numpy.random.SeedSequence

    Raises
    ------
    ParameterSpaceError (or ``error``)
        If ``seed`` is neither a SeedSequence nor a non-negative integer.
    """
    if isinstance(seed, np.random.SeedSequence):
        return seed
    if isinstance(seed, (int, np.integer)) and not isinstance(seed, bool) and seed >= 0:
        return np.random.SeedSequence(int(seed))
    raise (error or ParameterSpaceError)(
        f"{setting}: expected a non-negative integer or a numpy SeedSequence; got {seed!r}"
    )


def child_seed(seed_sequence: np.random.SeedSequence, index: int) -> np.random.SeedSequence:
    """Return the ``index``-th child of ``seed_sequence`` without changing its state.

    :meth:`SeedSequence.spawn` counts the children it has handed out, so
    calling it twice on the same object gives different streams; deriving the
    child from the spawn key keeps "same seed, same numbers" true however
    often an analysis is run.
    """
    return np.random.SeedSequence(
        entropy=seed_sequence.entropy,
        spawn_key=tuple(seed_sequence.spawn_key) + (int(index),),
        pool_size=seed_sequence.pool_size,
    )


def seed_attributes(seed_sequence: np.random.SeedSequence | None) -> dict[str, str]:
    """NetCDF-safe attributes describing a seed (entropy may exceed 64 bits, so strings)."""
    if seed_sequence is None:
        return {"seed_entropy": "none (deterministic)", "seed_spawn_key": ""}
    return {
        "seed_entropy": str(seed_sequence.entropy),
        "seed_spawn_key": json.dumps([int(k) for k in seed_sequence.spawn_key]),
    }
