"""The README as a new user follows it: its set-up command on a fresh clone, its examples as written.

The main job's run also serves the check that its report's headline is true of its
result files (the headline checks themselves are in tests/test_report_headline.py).

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
from test_report_headline import check_every_finding, check_page_order

from uqgear.report.finding import headline_html
from uqgear.report.headline import headline_findings

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


@pytest.fixture(scope="module")
def main_job(tmp_path_factory) -> tuple[subprocess.CompletedProcess, Path]:
    """The README's main job run once on a fresh clone: the process and its output folder."""
    command = _setup_command(1)
    install, _, main_job = command.partition(" && ")
    assert install.startswith("pip install"), command
    assert main_job.startswith("uqgear run "), command
    tmp_path = tmp_path_factory.mktemp("readme")
    clone = _fresh_clone(tmp_path / "clone")
    assert not (clone / "results").exists()
    arguments = main_job.split()[1:]
    environment = _environment(clone, tmp_path)
    if _carry_kernel_cache(clone):
        environment.pop("NUMBA_CACHE_DIR")
    completed = subprocess.run([sys.executable, "-m", "uqgear", *arguments], cwd=clone,
                               env=environment, capture_output=True, text=True, timeout=1200)
    return completed, clone / arguments[arguments.index("--out") + 1]


def test_the_first_setup_command_works_on_a_fresh_clone(main_job):
    completed, out = main_job
    assert completed.returncode == 0, completed.stderr[-3000:]
    report = (out / "report.html").read_text()
    assert "t2_envelope" in report and report.count("data:image/png;base64,") >= 3
    results = sorted(out.glob("*.nc"))
    assert len(results) >= 3
    with xr.open_dataset(results[0]) as ds:
        assert ds.attrs["numba_target_cpu"]


def test_t2_envelope_headline_is_true_of_its_netcdf_files(main_job):
    """The main job's headline, each statement recomputed from its result files (tests/test_report_headline.py)."""
    completed, folder = main_job
    assert completed.returncode == 0, completed.stderr[-3000:]
    text = (folder / "report.html").read_text()
    check_page_order(text)
    results = [xr.open_dataset(path) for path in sorted(folder.glob("*.nc"))]
    try:
        topics = check_every_finding(results)
        assert topics[:6] == ["rating", "rating", "worst_load", "separation", "separation", "back_contact"]
        assert "regimes" in topics and topics.count("sobol") == 2
        wet, dry = (finding for finding in headline_findings(results) if finding.topic == "separation")
        assert wet.text.startswith("Wet rail (T2 = 21.15 kN m") and dry.text.startswith("Dry rail (T2 = 46.52 kN m")
        # on dry rail the teeth separate over a narrower band of speeds than on wet rail
        (wet_low, wet_high), = wet.facts["ranges"]
        (dry_low, dry_high), = dry.facts["ranges"]
        assert wet_low < dry_low and dry_high < wet_high
        for finding in headline_findings(results):
            assert headline_html([finding]).split("<li>")[1].split("</li>")[0] in text
    finally:
        for ds in results:
            ds.close()


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
