"""Same input, same numbers: however the kernels were compiled, however many threads.

numba compiles the kernels on a first run and loads them from its on-disk
cache afterwards. With fast-math flags the two sets of machine code rounded
differently (last bits of every batch output), so a first run after install
disagreed with every later one. ``COLD_WARM_SCRIPT`` runs the batch kernel, the
calibration's harmonic kernel and the smoke study in a fresh interpreter; the
packaging test (tests/test_packaging.py) runs it with the installed wheel,
once with an empty cache and once with the cache it filled, and compares
every float bit for bit with :func:`differences` (one cold compilation
serves both checks: a cold compile of every kernel costs minutes).
"""

from __future__ import annotations

import textwrap
from pathlib import Path

import numpy as np
import xarray as xr

import uqgear

# Run in a fresh interpreter: the batch kernel through separation and period-n regimes, the
# calibration's harmonic kernel, and the smoke study through the real command line. One
# interpreter does all three, so each cache state costs one compilation.
COLD_WARM_SCRIPT = textwrap.dedent("""
    import sys
    import numpy as np
    import uqgear
    from uqgear.calibration import model_harmonics
    from uqgear.cli import main

    design = uqgear.load_design("locomotive")
    samples = uqgear.samples_from_mapping({
        "pinion_speed": np.linspace(1000.0, 5500.0, 8),
        "adhesion_torque": np.linspace(21e3, 46e3, 8),
    })
    batch = uqgear.simulate_batch(design, samples, n_periods=300, keep_periods=100, threads=2)
    arrays = {f"batch_{name}": batch[name].values for name in batch.data_vars
              if np.issubdtype(batch[name].dtype, np.floating)}
    harmonics = model_harmonics(design, samples.isel(sample=slice(0, 3)))
    arrays.update({f"harmonics_{name}": harmonics[name].values for name in harmonics.data_vars
                   if np.issubdtype(harmonics[name].dtype, np.floating)})
    np.savez(sys.argv[1], **arrays)
    sys.exit(main(["run", "smoke", "--out", sys.argv[2], "--quiet"]))
""")


def float_variables(path: Path) -> dict[str, np.ndarray]:
    with xr.open_dataset(path) as ds:
        return {name: ds[name].values.copy() for name in ds.variables
                if np.issubdtype(ds[name].dtype, np.floating)}


def differences(first: dict[str, np.ndarray], second: dict[str, np.ndarray]) -> list[str]:
    assert first.keys() == second.keys()
    # bit for bit: compare the raw bytes, so NaN payloads and signed zeros count too
    return [name for name in first
            if first[name].shape != second[name].shape
            or first[name].tobytes() != second[name].tobytes()]


def test_batch_is_bit_identical_on_one_and_two_threads():
    design = uqgear.load_design("locomotive")
    samples = uqgear.samples_from_mapping({"pinion_speed": np.linspace(1500.0, 5000.0, 6),
                                           "adhesion_torque": np.full(6, 25e3)})
    one = uqgear.simulate_batch(design, samples, n_periods=120, keep_periods=40, threads=1)
    two = uqgear.simulate_batch(design, samples, n_periods=120, keep_periods=40, threads=2)
    floats = [name for name in one.data_vars if np.issubdtype(one[name].dtype, np.floating)]
    assert len(floats) > 5
    assert differences({n: one[n].values for n in floats}, {n: two[n].values for n in floats}) == []


def test_results_record_the_cpu_the_kernels_were_compiled_for(tmp_path):
    from uqgear.uq.results import load_result, numba_target_cpu, save_result

    saved = save_result(xr.Dataset({"x": ("sample", np.arange(3.0))}), tmp_path / "r.nc", seed=1)
    loaded = load_result(saved)
    assert loaded.attrs["numba_target_cpu"] == numba_target_cpu() != ""
    assert "numba" in loaded.attrs["provenance_versions"]
    assert "llvmlite" in loaded.attrs["provenance_versions"]
