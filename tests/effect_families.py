"""Each effect family of the library at a setting that moves the response, for tests that run every family.

One table, so that a family added to the library is added to every such test at once.
"""

from __future__ import annotations

from uqgear.physics.effects import make_effect

FAMILIES = {
    "healthy": (),
    "eccentricity": (make_effect("eccentricity", {"amplitude": 12e-6, "kappa": 0.05}),),
    "tooth_damage": (make_effect("tooth_damage", {"depth": 0.3}),),
    "friction": (make_effect("friction", {"coefficient": 0.08}),),
    "torque_ripple": (make_effect("torque_ripple", {"amplitude": 0.05, "pole_pairs": 3}),),
    "adhesion_oscillation": (make_effect("adhesion_oscillation", {"amplitude": 0.05}),),
    # both bearings: the clearance's force term acts on both bearing rows of the Jacobian
    "bearing_clearance": (make_effect("bearing_clearance", {"clearance": 10e-6, "bearing": "both"}),),
}
