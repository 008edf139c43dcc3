"""Same input, same numbers: however the kernels were compiled, however many threads.

numba compiles the kernels on a first run and loads them from its on-disk
cache afterwards. With fast-math flags the two sets of machine code rounded
differently (last bits of every batch output), so a first run after install
disagreed with every later one. These tests run the batch kernel, the
calibration's harmonic kernel and the smoke study in fresh interpreters, once
with an empty cache and once with the cache it filled, and compare every float
bit for bit.
"""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
import xarray as xr

import uqgear.common
import uqgear

ROOT = Path(__file__).resolve().parent.parent
# the bundled studies, from the installed package (a wheel or sdist has no top-level studies/)
STUDIES = uqgear.common.bundled_file("study", "smoke").parent

# Kernels exercised in a fresh interpreter; arrays saved for comparison.
_KERNEL_SCRIPT = textwrap.dedent("""
    import sys
    import numpy as np
    import uqgear
    from uqgear.calibration import model_harmonics

    design = uqgear.load_design("locomotive")
    # speeds through the mesh resonance: separation, period-n and smooth runs
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
""")


def _fresh_interpreter(arguments: list[str], cache: Path, cwd: Path) -> None:
    environment = {**os.environ, "NUMBA_CACHE_DIR": str(cache), "UQGEAR_PROGRESS": "0",
                   "MPLBACKEND": "Agg"}
    completed = subprocess.run([sys.executable, *arguments], cwd=cwd, env=environment,
                               capture_output=True, text=True, timeout=900)
    assert completed.returncode == 0, completed.stderr[-3000:]


def _float_variables(path: Path) -> dict[str, np.ndarray]:
    with xr.open_dataset(path) as ds:
        return {name: ds[name].values.copy() for name in ds.variables
                if np.issubdtype(ds[name].dtype, np.floating)}


def _differences(first: dict[str, np.ndarray], second: dict[str, np.ndarray]) -> list[str]:
    assert first.keys() == second.keys()
    # bit for bit: compare the raw bytes, so NaN payloads and signed zeros count too
    return [name for name in first
            if first[name].shape != second[name].shape
            or first[name].tobytes() != second[name].tobytes()]


@pytest.mark.slow
def test_kernels_give_the_same_bits_on_a_cold_and_a_warm_cache(tmp_path):
    cache = tmp_path / "numba-cache"
    cache.mkdir()
    script = tmp_path / "kernels.py"
    script.write_text(_KERNEL_SCRIPT)
    _fresh_interpreter([str(script), str(tmp_path / "cold.npz")], cache, tmp_path)
    assert any(cache.rglob("*.nbi")), "the first run did not fill the numba cache"
    _fresh_interpreter([str(script), str(tmp_path / "warm.npz")], cache, tmp_path)
    cold, warm = np.load(tmp_path / "cold.npz"), np.load(tmp_path / "warm.npz")
    assert len(cold.files) > 10
    assert _differences({k: cold[k] for k in cold.files}, {k: warm[k] for k in warm.files}) == []


@pytest.mark.slow
def test_smoke_study_gives_the_same_bits_on_a_cold_and_a_warm_cache(tmp_path):
    cache = tmp_path / "numba-cache"
    cache.mkdir()
    study = STUDIES / "smoke.yaml"
    runs = []
    for name in ("cold", "warm"):
        _fresh_interpreter(["-m", "uqgear", "run", str(study), "--out", str(tmp_path / name)],
                           cache, tmp_path)
        runs.append(tmp_path / name)
    files = sorted(path.name for path in runs[0].glob("*.nc"))
    assert len(files) >= 8
    assert files == sorted(path.name for path in runs[1].glob("*.nc"))
    compared = 0
    for file in files:
        first, second = _float_variables(runs[0] / file), _float_variables(runs[1] / file)
        compared += len(first)
        assert _differences(first, second) == [], file
    assert compared > 50


def test_batch_is_bit_identical_on_one_and_two_threads():
    design = uqgear.load_design("locomotive")
    samples = uqgear.samples_from_mapping({"pinion_speed": np.linspace(1500.0, 5000.0, 6),
                                           "adhesion_torque": np.full(6, 25e3)})
    one = uqgear.simulate_batch(design, samples, n_periods=120, keep_periods=40, threads=1)
    two = uqgear.simulate_batch(design, samples, n_periods=120, keep_periods=40, threads=2)
    floats = [name for name in one.data_vars if np.issubdtype(one[name].dtype, np.floating)]
    assert len(floats) > 5
    assert _differences({n: one[n].values for n in floats}, {n: two[n].values for n in floats}) == []


def test_results_record_the_cpu_the_kernels_were_compiled_for(tmp_path):
    from uqgear.uq.results import load_result, numba_target_cpu, save_result

    saved = save_result(xr.Dataset({"x": ("sample", np.arange(3.0))}), tmp_path / "r.nc", seed=1)
    loaded = load_result(saved)
    assert loaded.attrs["numba_target_cpu"] == numba_target_cpu() != ""
    assert "numba" in loaded.attrs["provenance_versions"]
    assert "llvmlite" in loaded.attrs["provenance_versions"]
