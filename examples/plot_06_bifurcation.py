"""
Bifurcation diagram against pinion speed
========================================

The seed paper's central figure: the dynamic transmission error sampled once
per mesh period (the Poincare section) against pinion speed, at light load
(T1 = 1 kN m with the balancing T2), where the teeth separate and period-n,
quasi-periodic and chaotic responses appear. Each column is classified by its
Poincare period, the 0-1 test and the largest Lyapunov exponent together.
"""

import matplotlib.pyplot as plt
import numpy as np

from uqgear.dynamics import bifurcation

speeds = np.arange(2500.0, 6001.0, 25.0)
diagram = bifurcation(
    "locomotive",
    "pinion_speed",
    speeds,
    fixed={"drive_torque": 1000.0, "adhesion_torque": 4810.0},
    n_periods=800,
    keep_periods=200,
    lyapunov=True,
    seed=3,
)
regimes = diagram["regime"].values.astype(str)
families = np.where(
    np.char.startswith(regimes, "period-") & (regimes != "period-1"), "period-n", regimes
)
for family in np.unique(families):
    print(f"{family:32s} {np.sum(families == family):3d} speeds")
# contiguous speed ranges of the chaotic columns
chaotic = speeds[families == "chaotic"]
breaks = np.flatnonzero(np.diff(chaotic) > 25.0 + 1e-9)
ranges = np.split(chaotic, breaks + 1) if chaotic.size else []
print(
    "chaotic at "
    + ", ".join(f"{r[0]:.0f}-{r[-1]:.0f}" if r.size > 1 else f"{r[0]:.0f}" for r in ranges)
    + " rpm"
)

# %%
fig, ax = plt.subplots(figsize=(8, 4), constrained_layout=True)
half_backlash = diagram.attrs.get("half_backlash", 1.0)
for family, colour in zip(
    (
        "period-1",
        "period-n",
        "quasi-periodic",
        "quasi_periodic_or_long_period",
        "uncertain",
        "chaotic",
    ),
    ("tab:blue", "tab:green", "tab:orange", "tab:olive", "tab:grey", "tab:red"),
):
    columns = np.flatnonzero(families == family)
    if columns.size == 0:
        continue
    points = diagram["poincare_x"].values[columns] / half_backlash
    ax.plot(np.repeat(speeds[columns], points.shape[1]), points.ravel(), ",", color=colour)
    ax.plot([], [], "o", ms=4, color=colour, label=family)
ax.set_xlabel("pinion speed (rpm)")
ax.set_ylabel("DTE at mesh phase 0, x / b")
ax.legend(fontsize=8, ncol=3)
plt.show()
