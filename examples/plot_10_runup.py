"""
Run-up and coast-down through a coexistence window
==================================================

On wet rail (T2 = 21.1 kN m at T1 = 7 kN m) the locomotive gear holds two
steady responses between about 3570 and 3670 rpm. A run-up stays on the lower
branch until the fold where that branch ends and jumps up; a coast-down stays on
the upper branch down to the other fold and jumps down. The continuation finds
both folds; the ramps, whose forcing follows the pinion angle, show the jumps in
time, a little past the folds, by an amount that shrinks with the ramp rate. The
order map of the run-up's transmission error (computed order tracking) shows the
mesh order and its harmonics, and the jump in them.
"""

import matplotlib.pyplot as plt
import numpy as np

import uqgear
from uqgear.dynamics import Continuation

design = uqgear.load_design("locomotive")
inputs = {"drive_torque": 7000.0, "adhesion_torque": 21.1e3}
table = Continuation("pinion_speed", 3400.0, 3900.0).fit(design, inputs).result_
folds = {
    str(sweep): float(speed)
    for kind, sweep, speed in zip(
        table["bifurcation_type"].values, table["bifurcation_sweep"].values, table["bifurcation_parameter"].values
    )
    if kind == "fold" and sweep
}
print("folds of the period-1 branch:", {sense: round(speed, 1) for sense, speed in folds.items()})

# %%
# The two ramps at 60 rpm/s, binned in 5 rpm: the run-up jumps up near the upper fold, the coast-down down
# near the lower one.

edges = np.arange(3400.0, 3900.1, 5.0)
runs = {}
fig, ax = plt.subplots(figsize=(7, 3.8), constrained_layout=True)
for sense, (first, last) in (("up", (3400.0, 3900.0)), ("down", (3900.0, 3400.0))):
    ramp = uqgear.SpeedProfile.linear(first, last, rate_rpm_per_s=60.0 if sense == "up" else -60.0)
    runs[sense] = uqgear.simulate_runup(design, ramp, sample_rate=10240.0, **inputs)
    envelope = uqgear.ramp_envelope(runs[sense], speed_bins=edges)
    jumps = uqgear.jump_speeds(envelope, threshold=0.15, persistence=3)
    print(f"{sense:>4}: jumps at {[round(jump.speed) for jump in jumps]} rpm, fold at {folds[sense]:.0f} rpm")
    ax.step(envelope["pinion_speed"], envelope["peak_mesh_force"] / 1e3, where="mid", label=f"ramp {sense}")
for speed in folds.values():
    ax.axvline(speed, color="red", linewidth=0.8, linestyle=":")
ax.set_xlabel("pinion speed [rpm]")
ax.set_ylabel("peak mesh force per 5 rpm [kN]")
ax.set_title("Run-up and coast-down at 60 rpm/s; dotted: the continuation's folds", fontsize=9)
ax.legend()

# %%
# The order map of the run-up's transmission error: mesh order 21 and its harmonics, in 20 speed bins.

orders = uqgear.order_map(runs["up"], "te", np.arange(1.0, 64.0), speed_bins=20, revolutions_per_block=4)
fig, ax = plt.subplots(figsize=(7, 3.8), constrained_layout=True)
amplitude = orders["order_amplitude"].sel(signal="te").transpose("order", "pinion_speed")
mesh = ax.pcolormesh(
    orders["pinion_speed"], orders["order"], 20 * np.log10(amplitude / amplitude.max()), vmin=-60, cmap="magma"
)
fig.colorbar(mesh, ax=ax, label="amplitude [dB re peak]")
ax.set_xlabel("pinion speed [rpm]")
ax.set_ylabel("pinion order")
ax.set_title("Order map of the DTE along the run-up", fontsize=9)
