"""Draw the overview figure of the README and the documentation's front page.

It reads the results of the main job and writes ``docs/_static/overview.png``::

    uqgear run studies/t2_envelope.yaml --out results/t2_envelope
    python docs/_scripts/overview_figure.py results/t2_envelope docs/_static/overview.png
"""

from __future__ import annotations

import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import xarray as xr  # noqa: E402

#: Regime labels in the order of the colour scale, from orderly to disorderly.
REGIMES = (
    "period-1",
    "period-n",
    "quasi_periodic_or_long_period",
    "quasi-periodic",
    "uncertain",
    "chaotic",
)


def main(results: Path, target: Path) -> None:
    grid = xr.open_dataset(results / "regime_map.nc")
    speed = grid["pinion_speed"].values
    adhesion = grid["adhesion_torque"].values / 1e3
    force = grid["peak_mesh_force"].transpose("pinion_speed", "adhesion_torque").values / 1e3
    figure, (top, bottom) = plt.subplots(
        2, 1, figsize=(8.0, 5.6), sharex=True, constrained_layout=True
    )
    top.fill_between(
        speed,
        force.min(axis=1),
        force.max(axis=1),
        color="tab:blue",
        alpha=0.25,
        label=f"over T2 in [{adhesion.min():.1f}, {adhesion.max():.1f}] kN m",
    )
    top.plot(
        speed, force[:, 0], color="tab:blue", lw=1.2, label=f"wet rail, T2 = {adhesion[0]:.1f} kN m"
    )
    top.plot(
        speed,
        force[:, -1],
        color="tab:red",
        lw=1.2,
        label=f"dry rail, T2 = {adhesion[-1]:.1f} kN m",
    )
    top.set_ylabel("peak mesh force (kN)")
    top.set_title(
        "Bundled locomotive gear, drive torque 7 kN m: peak mesh force over the adhesion interval",
        fontsize=10,
    )
    top.legend(fontsize=8, loc="upper left")
    labels = grid["regime"].transpose("adhesion_torque", "pinion_speed").values.astype(str)
    # period-2, period-5, ... share one colour: the map shows where period-1 ends
    labels = np.where(
        np.char.startswith(labels, "period-") & (labels != "period-1"), "period-n", labels
    )
    present = [name for name in REGIMES if name in set(labels.ravel())]
    codes = np.array(
        [[present.index(label) if label in present else np.nan for label in row] for row in labels]
    )
    colours = plt.get_cmap("viridis", max(len(present), 2))
    bottom.pcolormesh(
        speed, adhesion, codes, cmap=colours, vmin=-0.5, vmax=len(present) - 0.5, shading="nearest"
    )
    handles = [plt.Rectangle((0, 0), 1, 1, color=colours(i)) for i in range(len(present))]
    bottom.legend(handles, present, fontsize=8, loc="upper left", ncol=3)
    bottom.set_ylabel("T2 (kN m)")
    bottom.set_xlabel("pinion speed (rpm)")
    bottom.set_title("Response regime on the speed x T2 grid", fontsize=10)
    figure.savefig(target, dpi=100)


if __name__ == "__main__":
    main(Path(sys.argv[1]), Path(sys.argv[2]))
