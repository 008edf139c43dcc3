"""
A polynomial chaos surrogate and its validation error
=====================================================

A polynomial chaos expansion (chaospy orthonormal basis, least-squares fit,
total degree chosen by leave-one-out error) of the RMS dynamic transmission
error at 2000 rpm over T2 and the mesh-stiffness tolerance. Its error is then
measured where it was not trained: at fresh random points, against the model.
"""

import matplotlib.pyplot as plt
import numpy as np

import uqgear

design = uqgear.load_design("locomotive")
space = uqgear.ParameterSpace(
    {
        "adhesion_torque": uqgear.Interval(*design.operation.adhesion_torque_bounds()),
        "mesh_stiffness_scale": uqgear.Interval(0.9, 1.1),
    }
)
model = uqgear.BatchEvaluator(
    design, fixed={"pinion_speed": 2000.0}, n_periods=300, keep_periods=100
)
pce = uqgear.PolynomialChaos(max_order=5, qoi=["dte_rms"], seed=11).fit(model, space)
result = pce.result_
print(
    f"chosen order {int(result['dte_rms_order'].item())}, "
    f"leave-one-out error {np.nanmin(result['dte_rms_loo_error'].values):.1e}, "
    f"training runs {pce.samples_.sizes['sample']}"
)
print(
    f"mean {result['dte_rms'].sel(statistic='mean').item() * 1e6:.3f} um, "
    f"std {result['dte_rms'].sel(statistic='std').item() * 1e6:.3f} um"
)

# %%
# Validation at 64 fresh points the surrogate has not seen.

check = space.sample(64, "monte_carlo", seed=12, interval_treatment="uniform")
truth = model(check)["dte_rms"].values
predicted = pce.predict(check)["dte_rms"].values
relative = np.sqrt(np.mean((predicted - truth) ** 2)) / np.std(truth)
print(f"validation error (RMS error / std) at 64 fresh points: {relative:.1e}")

fig, ax = plt.subplots(figsize=(4.5, 4.2), constrained_layout=True)
ax.plot(truth * 1e6, predicted * 1e6, "o", ms=4)
line = np.array([truth.min(), truth.max()]) * 1e6
ax.plot(line, line, color="grey", lw=0.8)
ax.set_xlabel("model: RMS DTE (um)")
ax.set_ylabel("surrogate: RMS DTE (um)")
ax.set_title(f"validation error {relative:.1e}")
plt.show()
