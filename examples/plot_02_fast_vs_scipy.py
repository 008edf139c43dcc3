"""
One simulation against the scipy reference
==========================================

The compiled fast path (RK4 on a whole number of steps per mesh period, with
stiffness jumps and contact crossings located inside the step) against the
scipy reference (DOP853 at rtol 1e-10 with events at the contact boundaries),
at a speed where the teeth separate on wet rail.
"""

import time

import matplotlib.pyplot as plt
import numpy as np

import uqgear

design = uqgear.load_design("locomotive")
kwargs = {
    "pinion_speed": 4000.0,
    "drive_torque": 7000.0,
    "adhesion_torque": 21.15e3,
    "n_periods": 300,
    "keep_periods": 20,
}
uqgear.simulate(design, **{**kwargs, "n_periods": 4, "keep_periods": 2})  # compile once

start = time.perf_counter()
fast = uqgear.simulate(design, **kwargs)
fast_seconds = time.perf_counter() - start
start = time.perf_counter()
reference = uqgear.simulate(design, **kwargs, method="scipy")
scipy_seconds = time.perf_counter() - start

x_fast, x_ref = fast["x"].values, reference["x"].values
error = np.sqrt(np.mean((x_fast - x_ref) ** 2)) / np.std(x_ref)
print(f"fast path {fast_seconds * 1e3:.0f} ms, scipy reference {scipy_seconds * 1e3:.0f} ms")
print(f"relative RMS difference of the DTE: {error:.1e}")
print(
    f"time in separation: fast {np.mean(fast['contact'] == 0):.1%}, "
    f"scipy {np.mean(reference['contact'] == 0):.1%}"
)

# %%
fig, (top, bottom) = plt.subplots(2, 1, figsize=(7, 4.5), sharex=True, constrained_layout=True)
t = fast["time"] * 1e3
b = fast.attrs["half_backlash"]
top.plot(t, x_ref / b, label="scipy reference", lw=2.5, alpha=0.5)
top.plot(t, x_fast / b, "--", label="fast path")
top.axhline(1.0, color="grey", lw=0.8)
top.set_ylabel("DTE x / b")
top.legend(loc="lower right")
bottom.plot(t, (x_fast - x_ref) / b)
bottom.set_ylabel("difference / b")
bottom.set_xlabel("time (ms)")
plt.show()
