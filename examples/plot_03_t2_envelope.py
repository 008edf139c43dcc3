"""
Peak mesh force over the adhesion interval
==========================================

The wheel/rail adhesion torque T2 is only known to lie in an interval (wet to
dry rail). Interval analysis bounds the peak mesh force and the time in
separation at every pinion speed over that interval, with no distribution
assumed: Chebyshev inclusion where the response is smooth in T2, a scan where
it is not (the points that fell back are counted).
"""

import matplotlib.pyplot as plt
import numpy as np

import uqgear

design = uqgear.load_design("locomotive")
lower, upper = design.operation.adhesion_torque_bounds()
print(
    f"T2 interval from the adhesion coefficient {design.operation.adhesion_coefficient}: "
    f"[{lower / 1e3:.1f}, {upper / 1e3:.1f}] kN m"
)

space = uqgear.ParameterSpace({"adhesion_torque": uqgear.Interval(lower, upper)})
model = uqgear.BatchEvaluator(
    design, fixed={"drive_torque": 7000.0}, n_periods=400, keep_periods=150
)
speeds = {"pinion_speed": np.arange(1000.0, 6001.0, 125.0)}
analysis = uqgear.IntervalAnalysis(
    "chebyshev",
    order=4,
    fallback="scan",
    scan_points=9,
    qoi=["peak_mesh_force", "fraction_separation"],
)
bounds = analysis.fit(model, space, sweep=speeds).result_

worst = bounds["peak_mesh_force"].sel(bound="upper")
separating = bounds["fraction_separation"].sel(bound="upper") > 0
print(
    f"worst-case peak mesh force {worst.max().item() / 1e3:.0f} kN at {worst.idxmax('pinion_speed').item():.0f} rpm"
)
print(
    f"teeth can separate somewhere in the interval at "
    f"{bounds['pinion_speed'].values[separating.values].min():.0f}-"
    f"{bounds['pinion_speed'].values[separating.values].max():.0f} rpm"
)
print(
    f"speeds bounded by the scan fallback: {int((bounds['flag'].values != 0).any(axis=0).sum())} "
    f"of {bounds.sizes['pinion_speed']}"
)

# %%
fig, (top, bottom) = plt.subplots(2, 1, figsize=(7, 5), sharex=True, constrained_layout=True)
speed = bounds["pinion_speed"]
force = bounds["peak_mesh_force"] / 1e3
top.fill_between(
    speed,
    force.sel(bound="lower"),
    force.sel(bound="upper"),
    alpha=0.3,
    label="over the T2 interval",
)
top.plot(speed, force.sel(bound="upper"), lw=1)
top.set_ylabel("peak mesh force (kN)")
top.legend()
separation = bounds["fraction_separation"]
bottom.fill_between(
    speed, separation.sel(bound="lower"), separation.sel(bound="upper"), alpha=0.3, color="tab:red"
)
bottom.set_ylabel("time in separation")
bottom.set_xlabel("pinion speed (rpm)")
plt.show()
