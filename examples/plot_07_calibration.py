"""
Bayesian calibration against a rig campaign, and a prediction with it
=====================================================================

The bundled healthy campaign (8 operating points from an independent virtual
rig whose true parameters are known) calibrated with emcee: mesh stiffness
scale, mesh damping, backlash, STE amplitude and both bearing stiffnesses, with
every run's adhesion torque as a latent parameter bounded by the file's
interval. Backlash cannot be identified from a campaign in which no run loses
contact: its posterior stays its prior.
The posterior is drawn with the true values; a posterior that has not converged
would be reported as such, without estimates. The posterior then enters a
prediction (below).
"""

import dataclasses

import matplotlib.pyplot as plt
import numpy as np

import uqgear
from uqgear.calibration.priors import prior_bounds

# the true parameters of the campaign, from the rig's own record (data/rig/README.md)
truth = {
    "mesh_stiffness_scale": 0.970,
    "zeta_mesh": 0.052,
    "backlash": 0.300e-3,
    "ste_amplitude": 16.07e-6,
    "k1": 1.010e9,
    "k2": 1.889e9,
}

calibration = uqgear.Calibration(list(truth), seed=5).fit(uqgear.example_rig_file())
print(
    f"converged: {calibration.converged_}; {calibration.model_runs_} model runs, "
    f"{calibration.timing_['wall_s']:.0f} s"
)
for name, value in truth.items():
    row = calibration.summary_["parameters"][name]
    inside = row["q05"] <= value <= row["q95"]
    print(
        f"{name:22s} truth {value:.4g}  90 % interval [{row['q05']:.4g}, {row['q95']:.4g}]  "
        f"{'inside' if inside else 'OUTSIDE'}"
    )

# %%
fig, axes = plt.subplots(1, len(truth), figsize=(12, 2.4), constrained_layout=True)
for ax, (name, value) in zip(axes, truth.items()):
    draws = calibration.posterior_[name].values.ravel()
    ax.hist(draws, bins=40, color="tab:blue", alpha=0.7)
    ax.axvline(value, color="tab:red", label="truth")
    ax.set_title(name, fontsize=9)
    ax.tick_params(labelsize=7)
axes[0].legend(fontsize=8)
plt.show()

# %%
# Predicting with the calibrated posterior
# ----------------------------------------
#
# After a calibration the rig data say more about the gear set than the design's
# tolerances do. The posterior above (joint draws of all six parameters) enters a
# prediction of the worst peak mesh force over the T2 interval (wet to dry rail)
# at speeds the campaign never ran (it covers 600-3800 rpm), beside the same from
# the calibration's prior: how far did the rig data narrow the worst case? The
# bundled study ``calibrated_prediction`` runs the whole chain from the command
# line: a diagnosis first, then the calibration with the diagnosed effect in the
# model, then the prediction.

design = uqgear.load_design("locomotive")
t2 = uqgear.Interval.from_adhesion(0.15, 0.33, 23000, 0.625)
posterior = uqgear.ParameterSpace.from_posterior(calibration, {"adhesion_torque": t2}, draws=32, seed=1)

# the same number of draws from the calibration's uniform prior box: the design's tolerances
box = prior_bounds(design, posterior.posterior.names)
rng = np.random.default_rng(2)
prior_values = np.stack([rng.uniform(*box[name], 32) for name in posterior.posterior.names], axis=1)
prior_draws = dataclasses.replace(posterior.posterior, values=prior_values)
prior = uqgear.ParameterSpace({"adhesion_torque": t2}, posterior=prior_draws)

model = uqgear.BatchEvaluator(design, fixed={"drive_torque": 7000.0}, n_periods=400, keep_periods=200)
speeds = {"pinion_speed": np.arange(1000.0, 6001.0, 250.0)}
predict = uqgear.PosteriorPrediction(["peak_mesh_force"], points=5, seed=3)
after = predict.fit(model, posterior, speeds).result_["peak_mesh_force"].sel(bound="upper") / 1e3
before = uqgear.PosteriorPrediction(["peak_mesh_force"], points=5, seed=3).fit(model, prior, speeds)
before = before.result_["peak_mesh_force"].sel(bound="upper") / 1e3

worst = int(after.sel(quantile=0.5).argmax())
low, high = (float(before.isel(quantile=q, pinion_speed=worst)) for q in (0, -1))
print(
    f"worst peak mesh force over T2 at {speeds['pinion_speed'][worst]:.0f} rpm: {low:.0f}-{high:.0f} kN from the "
    f"tolerances, {float(after.isel(quantile=0, pinion_speed=worst)):.0f}-"
    f"{float(after.isel(quantile=-1, pinion_speed=worst)):.0f} kN after calibration (5-95 %)"
)

# %%
fig, ax = plt.subplots(figsize=(8, 3.2), constrained_layout=True)
x = speeds["pinion_speed"]
ax.fill_between(x, before.isel(quantile=0), before.isel(quantile=-1), color="0.8", label="prior (tolerances), 5-95 %")
ax.fill_between(
    x, after.isel(quantile=0), after.isel(quantile=-1), color="tab:blue", alpha=0.7, label="after calibration"
)
ax.axvspan(600, 3800, color="tab:green", alpha=0.08, label="the campaign's speeds")
ax.set_xlabel("pinion speed [rpm]")
ax.set_ylabel("worst peak mesh force over T2 [kN]")
ax.legend(fontsize=8)
plt.show()
