"""
Bayesian calibration against a rig campaign
===========================================

The bundled healthy campaign (8 operating points from an independent virtual
rig whose true parameters are known) calibrated with emcee: mesh stiffness
scale, mesh damping, backlash, STE amplitude and both bearing stiffnesses, with
every run's adhesion torque as a latent parameter bounded by the file's
interval. Backlash cannot be identified from a campaign in which no run loses
contact: its posterior stays its prior.
The posterior is drawn with the true values; a posterior that has not converged
would be reported as such, without estimates.
"""

import matplotlib.pyplot as plt

import uqgear

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
