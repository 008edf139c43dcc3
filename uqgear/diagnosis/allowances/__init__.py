"""What a rig campaign holds that is no effect of the library, taken into the comparison so that it is never named.

One module per allowance, each an object with the common interface
:class:`Allowance`: its ``key`` in ``diagnosis.json``, whether it was
``applied`` and its JSON-ready ``summary()``. They act at three points of
the diagnosis (docs/model/unmodelled-effects.md section 6):

- on the records, as the features are extracted (step 1): line
  interference on the accelerometers, left out of the low band
  (:mod:`.interference`);
- on the model's features, before any fit (step 1): a healthy reference
  campaign's transfer correction (:mod:`.reference`, its gain curves in
  :mod:`.gain_curve`), whose ``apply(case)`` returns the corrected case;
- on the model error, after the nominal fit (step 3): the manufactured
  gears' pitch errors (:mod:`.pitch_errors`, scaled to the rig's own gears
  order by order in :mod:`.pitch_orders`), whose ``apply(case)`` returns the
  case with the widened error; and, after the set is decided (step 6), the
  sideband phase test that tells an eccentric shaft from those pitch errors
  (:mod:`.sideband_phase`).

The modules import the diagnosis's case, fits and scores; this package's
``__init__`` imports none of them, so the case may import an allowance.
"""

from __future__ import annotations

from typing import Any, Protocol


class Allowance(Protocol):
    """The common interface of the allowances: an entry of ``diagnosis.json`` and whether it acted."""

    @property
    def key(self) -> str:
        """Its key in ``diagnosis.json``."""
        ...

    @property
    def applied(self) -> bool:
        """Whether it changed the comparison."""
        ...

    def summary(self) -> Any:
        """JSON-ready record (its entry in ``diagnosis.json``)."""
        ...


__all__ = ["Allowance"]
