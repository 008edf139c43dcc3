"""Rig files of the foreign virtual rig: what ``uqgear synth-rig --foreign GRADE`` writes.

:func:`synth_foreign_rig` draws one gear set of an ISO 1328-1 quality grade
(:func:`~.foreign_rig.draw_gears`) and records either a steady campaign at
the default operating points (:func:`~.foreign_rig.simulate_foreign_campaign`)
or ramp records (:func:`~.foreign_runup.simulate_foreign_runup_campaign`).

Seeds: one SeedSequence per call; child 0 of the gear seed's sequence draws
the gears, child 1 of the seed's sequence records the campaign. The gear seed
is the seed unless given, so a steady and a run-up campaign of one seed run
the same gears, and a healthy reference and a test campaign of the same gear
seed and different seeds run the same gears with other noise and record
starts, as a differential diagnosis (``diagnose --reference``) takes them.
"""

from __future__ import annotations

import json
import os
from collections.abc import Mapping, Sequence
from pathlib import Path

from numpy.typing import ArrayLike

from ..common.errors import RigDataError
from ..physics.design import Design
from ..physics.effects import Effect
from ..uq.seeds import SeedLike, as_seed_sequence, child_seed, seed_attributes
from .foreign_rig import draw_gears, effect_vector, simulate_foreign_campaign
from .foreign_runup import simulate_foreign_runup_campaign
from .format import write_rig
from .virtual_rig import default_operating_points

#: ISO 1328-1:2013 flank tolerance classes, finest and coarsest.
ISO_1328_CLASSES = (1.0, 11.0)
#: Length of each steady record, s (the foreign suite's and the steady virtual rig's).
STEADY_DURATION = 1.0


def synth_foreign_rig(
    design: Design,
    out_path: str | os.PathLike[str],
    grade: float,
    *,
    ramps: Mapping[str, ArrayLike] | None = None,
    effects: Sequence[Effect] = (),
    seed: SeedLike = 0,
    gears_seed: SeedLike | None = None,
    relative_noise: float = 0.02,
    option: str = "grade",
) -> Path:
    """Simulate a campaign of the foreign virtual rig and write it atomically as a rig file.

    Parameters
    ----------
    design : Design
        Nominal design (stored in the file) and the foreign rig's gearbox.
    out_path : str or path-like
        Target ``.nc`` file; its folder must exist.
    grade : float
        ISO 1328-1 flank tolerance class of the drawn per-tooth profile errors, 1 to 11.
    ramps : mapping, optional
        A ramp table (:func:`~uqgear.rig.virtual_runup.parse_ramps`): ramp records instead of
        steady runs at :func:`~uqgear.rig.virtual_rig.default_operating_points`
        (records of :data:`STEADY_DURATION`).
    effects : sequence of Effect
        Effects with physics on the foreign rig (:func:`~uqgear.rig.foreign_rig.register_foreign_physics`).
    seed : int or SeedSequence
        Seed of the noise and the record starts (child 1 of its SeedSequence).
    gears_seed : int or SeedSequence, optional
        Seed of the gear set (child 0 of its SeedSequence); default ``seed``.
    relative_noise : float
        White sensor noise as a fraction of each clean record's RMS.
    option : str
        The name a refused ``grade`` goes by in the message (the command line's option).

    Returns
    -------
    pathlib.Path
        The file written, with the attributes ``foreign_grade``, ``foreign_gears``,
        ``foreign_gears_seed`` (entropy and spawn key of the gears' seed), ``effects``,
        ``seed_entropy`` and ``seed_spawn_key`` (the campaign's seed).

    Raises
    ------
    RigDataError
        A grade outside 1 to 11, a bad seed, an effect without foreign physics or a missing folder,
        before anything is simulated.
    OperatingPointError
        A ramp the foreign rig cannot run (naming its key).

    Examples
    --------
    >>> import json, pathlib, tempfile
    >>> from uqgear.physics.design import load_design
    >>> from uqgear.rig.format import read_rig
    >>> design = load_design("locomotive")
    >>> ramps = {"start_speed": [1500.0], "stop_speed": [1600.0], "duration": [0.2], "drive_torque": [7000.0]}
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     path = synth_foreign_rig(design, pathlib.Path(folder) / "ramp.nc", 6, ramps=ramps, seed=3)
    ...     rig = read_rig(path)
    ...     print(rig.attrs["foreign_grade"], len(json.loads(rig.attrs["foreign_gears"])["pinion"]) == design.z1)
    6.0 True
    """
    path = Path(out_path)
    if not path.parent.is_dir():
        raise RigDataError(f"{path}: folder {path.parent} does not exist")
    low, high = ISO_1328_CLASSES
    if isinstance(grade, bool) or not isinstance(grade, (int, float)) or not (low <= grade <= high):
        raise RigDataError(f"{option}: expected an ISO 1328-1 flank tolerance class from {low:g} to {high:g}; "
                           f"got {grade!r}")
    sequence = as_seed_sequence(seed, error=RigDataError)
    gears_sequence = sequence if gears_seed is None else as_seed_sequence(gears_seed, setting="gears_seed",
                                                                          error=RigDataError)
    effect_vector(effects, design)  # an effect without foreign physics is refused before any run
    gears_child, campaign_seed = child_seed(gears_sequence, 0), child_seed(sequence, 1)
    gears = draw_gears(design, float(grade), gears_child)
    if ramps is None:
        ds = simulate_foreign_campaign(design, default_operating_points(design), gears=gears, effects=effects,
                                       seed=campaign_seed, duration=STEADY_DURATION, relative_noise=relative_noise)
    else:
        ds = simulate_foreign_runup_campaign(design, ramps, gears=gears, effects=effects, seed=campaign_seed,
                                             relative_noise=relative_noise)
    gear_attributes = seed_attributes(gears_child)
    ds.attrs.update(
        foreign_grade=float(grade),
        foreign_gears_seed=json.dumps({"entropy": gear_attributes["seed_entropy"],
                                       "spawn_key": json.loads(gear_attributes["seed_spawn_key"])}),
        **seed_attributes(campaign_seed),
    )
    return write_rig(path, ds)


__all__ = ["ISO_1328_CLASSES", "STEADY_DURATION", "synth_foreign_rig"]
