"""
Which uncertainty matters: Sobol indices
========================================

First- and total-order Sobol indices (SALib, Saltelli design, bootstrap
confidence intervals) of the RMS dynamic transmission error at two speeds:
2000 rpm, well below the mesh resonance, and 3800 rpm, inside the wet-rail
window where teeth separate. Interval parameters are treated as uniform on
their bounds for this purpose only.
"""

import matplotlib.pyplot as plt
import numpy as np

import uqgear

design = uqgear.load_design("locomotive")
space = uqgear.ParameterSpace(
    {
        "adhesion_torque": uqgear.Interval(*design.operation.adhesion_torque_bounds()),
        "mesh_stiffness_scale": uqgear.Interval(0.9, 1.1),
        "zeta_mesh": uqgear.Interval(0.03, 0.08),
        "k1": uqgear.Interval(0.7e9, 1.3e9),
    }
)
names = list(space.names)
fig, axes = plt.subplots(1, 2, figsize=(8, 3.5), sharey=True, constrained_layout=True)
for ax, speed in zip(axes, (2000.0, 3800.0)):
    model = uqgear.BatchEvaluator(
        design, fixed={"pinion_speed": speed}, n_periods=300, keep_periods=100
    )
    result = (
        uqgear.SobolAnalysis(n_base=64, qoi=["dte_rms"], seed=7, num_resamples=100)
        .fit(model, space)
        .result_
    )
    total = result["dte_rms"].sel(index="ST")
    first = result["dte_rms"].sel(index="S1")
    print(
        f"{speed:.0f} rpm, total-order indices: "
        + ", ".join(f"{name} {total.sel(param=name).item():.2f}" for name in names)
    )
    position = np.arange(len(names))
    ax.bar(position - 0.2, first.sel(param=names), width=0.4, label="first order S1")
    ax.bar(position + 0.2, total.sel(param=names), width=0.4, label="total ST")
    ax.set_xticks(position, [name.replace("_", "\n") for name in names], fontsize=8)
    ax.set_title(f"{speed:.0f} rpm")
axes[0].set_ylabel("Sobol index of the RMS DTE")
axes[0].legend()
plt.show()
