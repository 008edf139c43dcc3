"""
Diagnosis of a rig campaign
===========================

The bundled eccentricity campaign (an independent virtual rig with a 12 um
pinion run-out) diagnosed: the nominal model is fitted, the held-out gap mapped
over run x channel x feature family, each candidate effect of the library
fitted on top and scored on runs it was not fitted to. The verdict names the
effect the evidence supports, with its fitted parameters and their intervals.
"""

import matplotlib.pyplot as plt

import uqgear

rig = uqgear.example_rig_file("eccentricity")
diagnosis = uqgear.Diagnosis(seed=0).fit(rig)   # settings in the constructor, the work in fit
summary = diagnosis.to_dict()                   # what diagnosis.json holds
gap_map = diagnosis.result_                     # what diagnosis.nc holds

print(f"verdict: {summary['verdict']}")
print(f"reason:  {summary['reason']}")
for effect in summary["effects"]:
    print(f"named {effect['variant']}, share of the gap {effect['shrink_share']:.0%}:")
    for name, (low, high) in effect["parameter_intervals"].items():
        print(
            f"  {name:10s} {effect['parameters'][name]:.4g}  (90 % interval {low:.4g} to {high:.4g})"
        )
print("candidates, best first:")
for entry in summary["ranking"]:
    print(
        f"  {entry['effect']:22s} held-out score {entry['score']:8.1f} nats, "
        f"shrinks the gap by {max(entry['shrink_fraction'], 0.0):.0%}"
    )

# %%
# Where the nominal model misses: the held-out discrepancy per run, channel and feature family.

grid = gap_map["gap_map_nominal"]
fig, axes = plt.subplots(
    1, grid.sizes["channel"], figsize=(10, 3.2), sharey=True, constrained_layout=True
)
for ax, channel in zip(axes, grid["channel"].values):
    image = ax.imshow(
        grid.sel(channel=channel).transpose("family", "op").values, aspect="auto", cmap="magma"
    )
    ax.set_title(str(channel), fontsize=9)
    ax.set_xlabel("operating point")
axes[0].set_yticks(range(grid.sizes["family"]), grid["family"].values, fontsize=7)
fig.colorbar(image, ax=axes, label="held-out gap of the nominal model")
plt.show()
