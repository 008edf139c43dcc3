"""
Ishikawa mesh stiffness
=======================

The time-varying mesh stiffness k(t) of the bundled locomotive gear by the
Ishikawa method: each tooth a cantilever (rectangle plus trapezoid) with
bending, shear, foundation and contact compliances, pairs summed over the path
of contact. The mean is compared with ISO 6336-1's mesh stiffness, and the
truncated Fourier series the model can use instead of the raw curve is drawn
over it.
"""

import matplotlib.pyplot as plt

import uqgear

design = uqgear.load_design("locomotive")
stiffness = uqgear.mesh_stiffness(design)

k_mean = stiffness.attrs["k_mean"]
iso = uqgear.iso6336_stiffness(design)
print(f"contact ratio               {stiffness.attrs['contact_ratio']:.3f}")
print(
    f"Ishikawa mean stiffness     {k_mean / 1e9:.3f} GN/m (range {stiffness.attrs['k_min'] / 1e9:.2f}"
    f"-{stiffness.attrs['k_max'] / 1e9:.2f})"
)
print(
    f"ISO 6336-1 c_gamma b        {iso['mesh_stiffness'] / 1e9:.3f} GN/m "
    f"(c' = {iso['c_prime']:.2f}, c_gamma = {iso['c_gamma']:.2f} N/(mm um))"
)
print(f"ratio Ishikawa / ISO        {k_mean / iso['mesh_stiffness']:.3f}")

# %%
# One mesh period: two pairs in contact while the phase is below eps - 1, one pair after.

fig, ax = plt.subplots(figsize=(7, 3.5), constrained_layout=True)
phase = stiffness["mesh_phase"]
ax.plot(phase, stiffness["mesh_stiffness"] / 1e9, label="Ishikawa k(t)")
ax.plot(
    phase,
    stiffness["mesh_stiffness_fourier"] / 1e9,
    "--",
    label=f"Fourier series, {stiffness.attrs['n_harmonics']} harmonics",
)
ax.axhline(iso["mesh_stiffness"] / 1e9, color="grey", lw=0.8, label="ISO 6336-1 c_gamma b")
ax.set_xlabel("mesh phase (mesh periods)")
ax.set_ylabel("mesh stiffness (GN/m)")
ax.legend()
plt.show()
