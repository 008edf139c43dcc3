"""The README as a new user follows it: its set-up command on a fresh clone, its examples as written.

Commands and code are read from README.md itself, so the README cannot drift
from what is tested.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
import xarray as xr

ROOT = Path(__file__).resolve().parent.parent
README = (ROOT / "README.md").read_text()
pytestmark = pytest.mark.slow


def _environment(source: Path, cwd: Path) -> dict[str, str]:
    """The environment of a README command run on the package at ``source``.

    A clone elsewhere compiles its kernels afresh, into a cache of its own;
    the checkout itself keeps the suite's cache (its kernels were compiled
    by the tests before: another cold compile would check nothing new and
    cost minutes).
    """
    environment = {key: value for key, value in os.environ.items() if key != "PYTHONHOME"}
    environment.update({"PYTHONPATH": str(source), "UQGEAR_PROGRESS": "0", "MPLBACKEND": "Agg"})
    if source.resolve() != ROOT.resolve():
        environment["NUMBA_CACHE_DIR"] = str(cwd / ".numba-cache")
    return environment


def _setup_command(number: int) -> str:
    """The shell command of set-up step ``number`` (the line after its ``# N.`` comment)."""
    block = re.search(r"## Set-up.*?```bash\n(.*?)```", README, re.S)
    assert block, "README: no bash block under '## Set-up'"
    lines = block.group(1).splitlines()
    for index, line in enumerate(lines):
        if line.startswith(f"# {number}."):
            return lines[index + 1].strip()
    raise AssertionError(f"README: set-up step {number} not found")


def _fresh_clone(target: Path) -> Path:
    """A clone of the committed tree (or, outside git, a copy without ignored folders)."""
    if (ROOT / ".git").exists() and shutil.which("git"):
        subprocess.run(["git", "clone", "--quiet", str(ROOT), str(target)], check=True, timeout=300)
        # the clone has what is committed; carry the working tree's uncommitted edits of tracked files
        # too, so the test checks this code (files git ignores stay behind, as in a user's clone)
        changed = subprocess.run(["git", "-C", str(ROOT), "ls-files", "--modified", "--others",
                                  "--exclude-standard"], capture_output=True, text=True, check=True).stdout
        for name in changed.splitlines():
            source = ROOT / name
            if source.is_file() and not source.is_symlink():
                (target / name).parent.mkdir(parents=True, exist_ok=True)
                shutil.copy2(source, target / name)
    else:
        shutil.copytree(ROOT, target, symlinks=True,
                        ignore=shutil.ignore_patterns("results", "__pycache__", ".pytest_cache", "*.egg-info"))
    return target


def _carry_kernel_cache(clone: Path) -> int:
    """Give the clone the checkout's compiled kernels where its sources are the same; the number carried.

    numba keeps a module's compiled kernels beside it (``__pycache__/*.nbi``,
    ``*.nbc``, when no ``NUMBA_CACHE_DIR`` is set, as in CI) and uses them
    while the source file has the same size and modification time. A cold
    compilation of every kernel costs minutes and is checked by
    tests/test_packaging.py; here it would check nothing about the clone. A
    source that differs (or a checkout without such a cache) compiles afresh.
    """
    carried = 0
    for index in (ROOT / "uqgear").rglob("__pycache__/*.nbi"):
        module = index.name.split(".")[0]
        source = index.parent.parent / f"{module}.py"
        target_source = clone / source.relative_to(ROOT)
        if not source.is_file() or not target_source.is_file() or \
                source.read_bytes() != target_source.read_bytes():
            continue
        target_cache = target_source.parent / "__pycache__"
        target_cache.mkdir(exist_ok=True)
        stem = index.name[:-len(".nbi")]
        for cached in [index, *index.parent.glob(f"{stem}.*.nbc")]:
            shutil.copy2(cached, target_cache / cached.name)
        stat = source.stat()
        os.utime(target_source, ns=(stat.st_atime_ns, stat.st_mtime_ns))
        carried += 1
    return carried


def test_the_first_setup_command_works_on_a_fresh_clone(tmp_path):
    command = _setup_command(1)
    install, _, main_job = command.partition(" && ")
    assert install.startswith("pip install"), command
    assert main_job.startswith("uqgear run "), command
    clone = _fresh_clone(tmp_path / "clone")
    assert not (clone / "results").exists()
    arguments = main_job.split()[1:]
    environment = _environment(clone, tmp_path)
    if _carry_kernel_cache(clone):
        environment.pop("NUMBA_CACHE_DIR")
    completed = subprocess.run([sys.executable, "-m", "uqgear", *arguments], cwd=clone,
                               env=environment, capture_output=True, text=True, timeout=1200)
    assert completed.returncode == 0, completed.stderr[-3000:]
    out = clone / arguments[arguments.index("--out") + 1]
    report = (out / "report.html").read_text()
    assert "t2_envelope" in report and report.count("data:image/png;base64,") >= 3
    results = sorted(out.glob("*.nc"))
    assert len(results) >= 3
    with xr.open_dataset(results[0]) as ds:
        assert ds.attrs["numba_target_cpu"]


def test_the_python_examples_run_as_written(tmp_path):
    blocks = re.findall(r"```python\n(.*?)```", README, re.S)
    assert len(blocks) >= 2, "README: expected the simulation and the uncertainty examples"
    script = tmp_path / "examples.py"
    script.write_text("\n\n".join(blocks))
    completed = subprocess.run([sys.executable, str(script)], cwd=tmp_path, env=_environment(ROOT, tmp_path),
                               capture_output=True, text=True, timeout=900)
    assert completed.returncode == 0, completed.stderr[-3000:]
    # the uncertainty example prints the total-effect Sobol indices: T2 leads at 2000 rpm
    assert re.search(r"adhesion_torque\s+0\.[5-9]", completed.stdout), completed.stdout
