"""The ``uqgear`` command line end to end: real runs in temporary folders, bad input, resume."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
import xarray as xr
from helpers import cli_in_process as _cli

import uqgear.common
from uqgear.cli import main
from uqgear.common.errors import UqgearError
from uqgear.study import analyses, running
from uqgear.study.schema import load_study, parse_study
from uqgear.uq.results import load_result
from uqgear.uq.runner import Runner

ROOT = Path(__file__).resolve().parent.parent
# the bundled studies, from the installed package (a wheel or sdist has no top-level studies/)
STUDIES = uqgear.common.bundled_file("study", "smoke").parent
SMOKE = STUDIES / "smoke.yaml"
ENVIRONMENT = {**os.environ, "UQGEAR_PROGRESS": "0", "MPLBACKEND": "Agg"}

# A tiny study for in-process runs: two cheap analyses.
TINY = """
name: tiny
seed: 5
operating_points: {pinion_speed: [3000, 4000], drive_torque: 1000}
uncertain: {adhesion_torque: {interval: [20000, 40000]}}
simulation: {n_periods: 60, keep_periods: 24}
analyses:
  - {type: bifurcation, parameter: pinion_speed}
  - {type: monte_carlo, samples: 4}
"""


def uqgear(*arguments: str, cwd: Path | None = None) -> subprocess.CompletedProcess:
    """Run the real command line in a fresh interpreter."""
    return subprocess.run([sys.executable, "-m", "uqgear", *map(str, arguments)], cwd=cwd or ROOT,
                          env=ENVIRONMENT, capture_output=True, text=True, timeout=300)


def leftovers(out: Path) -> list[Path]:
    """Anything a run into ``out`` left next to it (partial folders)."""
    return [path for path in out.parent.iterdir() if path.name.startswith(f".{out.name}")]


@pytest.fixture(scope="module")
def smoke_run(smoke_study_run) -> Path:
    """The bundled smoke study run by name through the real command line, into a new nested folder.

    ``uqgear run smoke --out results/deeper/smoke`` from an empty folder (tests/conftest.py: one run
    serves every test file that reads it).
    """
    completed, out = smoke_study_run
    assert completed.returncode == 0, completed.stderr
    assert completed.args[1:] == ["run", "smoke", "--out", str(Path("results") / "deeper" / "smoke")]
    assert f"results written to {Path('results') / 'deeper' / 'smoke'}" in completed.stdout
    return out


# ---------------------------------------------------------------------------- end to end


@pytest.mark.slow
def test_run_writes_one_result_per_analysis_and_a_report(smoke_run):
    study = load_study(SMOKE)
    names = sorted(f"{spec.name}.nc" for spec in study.analyses)
    assert sorted(path.name for path in smoke_run.glob("*.nc")) == names
    assert (smoke_run / "report.html").is_file()
    assert not (smoke_run / ".checkpoints").exists()
    assert not leftovers(smoke_run)
    seeds = study.seed_sequences()
    for spec in study.analyses:
        result = load_result(smoke_run / f"{spec.name}.nc")
        assert result.attrs["analysis_type"] == spec.type
        assert result.attrs["seed"] == str(study.seed)
        assert result.attrs["seed_spawn_key"] == f"[{spec.index}]" == str(list(seeds[spec.index].spawn_key))
        assert result.attrs["study"] == SMOKE.read_text()
        assert '"z1": 21' in result.attrs["design"]
        assert result.attrs["run_time_s"] > 0
    envelope = load_result(smoke_run / "envelope.nc")
    bounds = envelope["dte_rms"]
    assert bounds.dims == ("pinion_speed", "bound")
    assert np.all(bounds.sel(bound="lower") <= envelope["dte_rms_nominal"] + 1e-12)
    assert np.all(envelope["dte_rms_nominal"] <= bounds.sel(bound="upper") + 1e-12)
    regime = load_result(smoke_run / "regime_map.nc")
    assert regime["regime"].dims == ("pinion_speed", "adhesion_torque")
    t2 = study.uncertain["adhesion_torque"]
    np.testing.assert_allclose(regime["adhesion_torque"], np.linspace(t2.lower, t2.upper, 3))


@pytest.mark.slow
def test_report_is_rebuilt_from_the_saved_results_alone(smoke_run, tmp_path, capsys):
    copy = tmp_path / "copy"
    copy.mkdir()
    for path in smoke_run.glob("*.nc"):
        shutil.copy2(path, copy)
    assert main(["report", str(copy)]) == 0
    assert capsys.readouterr().out == f"report written to {copy / 'report.html'}\n"
    rebuilt = (copy / "report.html").read_text()
    for spec in load_study(SMOKE).analyses:
        assert f'id="analysis-{spec.name}"' in rebuilt


@pytest.mark.slow
def test_resume_of_a_finished_run_reuses_every_analysis(smoke_run, tmp_path, monkeypatch):
    copy = tmp_path / "again"
    shutil.copytree(smoke_run, copy)
    created = {path.name: load_result(path).attrs["created"] for path in copy.glob("*.nc")}
    # nothing may be computed again: every analysis function would fail
    for kind in list(analyses.ANALYSES):
        monkeypatch.setitem(analyses.ANALYSES, kind, None)
    assert main(["run", str(SMOKE), "--out", str(copy), "--resume", "--quiet"]) == 0
    assert {path.name: load_result(path).attrs["created"] for path in copy.glob("*.nc")} == created
    assert not leftovers(copy)


def test_user_mistake_exits_2_with_one_line_and_no_output(tmp_path):
    study = tmp_path / "bad.yaml"
    study.write_text(SMOKE.read_text().replace("method: chebyshev", "method: chebychev"))
    out = tmp_path / "out"
    completed = uqgear("run", study, "--out", out)
    assert completed.returncode == 2
    assert completed.stderr == (f"uqgear: error: {study}: analyses[3].method: expected one of scan, vertex, "
                                "chebyshev, optimize; got 'chebychev'\n")
    assert "Traceback" not in completed.stderr and completed.stdout == ""
    assert not out.exists() and not leftovers(out)


def test_console_script_is_installed():
    script = shutil.which("uqgear")
    if script is None:
        pytest.skip("the uqgear console script is not on PATH (package not installed)")
    completed = subprocess.run([script, "validate", str(SMOKE)], capture_output=True, text=True, env=ENVIRONMENT,
                               timeout=120)
    assert completed.returncode == 0
    assert "valid study 'smoke' with 12 analyses" in completed.stdout


# ---------------------------------------------------------------------------- bad input, in-process


def write(tmp_path: Path, text: str, name: str = "study.yaml") -> Path:
    path = tmp_path / name
    path.write_text(textwrap.dedent(text))
    return path


BAD_RUNS = [
    ("analyses: [{type: interval, method: chebychev}]\nuncertain: {adhesion_torque: {interval: [2.0e4, 4.0e4]}}",
     "analyses[0].method: expected one of scan, vertex, chebyshev, optimize; got 'chebychev'"),
    ("analyses: [{type: simulate}\n", "not valid YAML at line 2"),
    ("analyses: [{type: simulate, operating_points: {pinion_speed: -100}}]",
     "analyses[0].operating_points.pinion_speed: expected a number in (0, 100000] rpm; got -100"),
    ("design: {name: locomotiv}\nanalyses: [{type: simulate}]", "design: design 'locomotiv': not a bundled design"),
    ("operating_points: {pinion_speed: 3000}\nanalyses: [{type: sobol}]",
     "analyses[0].parameters: no uncertain parameters to propagate"),
    ("unknown_key: 1\nanalyses: [{type: simulate}]", "unknown_key: unknown key; expected one of name"),
]


@pytest.mark.parametrize("text, message", BAD_RUNS)
def test_bad_study_gives_status_2_one_line_and_no_output(tmp_path, capsys, text, message):
    study = write(tmp_path, text)
    out = tmp_path / "out"
    assert main(["run", str(study), "--out", str(out)]) == 2
    captured = capsys.readouterr()
    assert captured.err.startswith(f"uqgear: error: {study}: ")
    assert message in captured.err
    assert captured.err.count("\n") == 1 and captured.out == ""
    assert not out.exists() and not leftovers(out)


def test_missing_study_file(tmp_path, capsys):
    out = tmp_path / "out"
    assert main(["run", str(tmp_path / "absent.yaml"), "--out", str(out)]) == 2
    error = capsys.readouterr().err
    assert error.startswith(f"uqgear: error: {tmp_path / 'absent.yaml'}: study file not found (bundled studies")
    assert error.count("\n") == 1 and "smoke" in error
    assert not out.exists()
    assert main(["validate", str(tmp_path / "absent.yaml")]) == 2


def test_non_empty_output_folder_is_refused_without_resume(tmp_path, capsys):
    out = tmp_path / "out"
    out.mkdir()
    (out / "keep.txt").write_text("mine")
    study = write(tmp_path, TINY)
    assert main(["run", str(study), "--out", str(out)]) == 2
    assert "folder exists and is not empty" in capsys.readouterr().err
    assert [path.name for path in out.iterdir()] == ["keep.txt"]
    # missing folders above a new output folder are made (a fresh clone has no results/)
    assert main(["run", str(study), "--out", str(out / "missing" / "deeper")]) == 0
    assert (out / "missing" / "deeper" / "report.html").is_file()
    assert sorted(path.name for path in out.iterdir()) == ["keep.txt", "missing"]


def test_argument_errors_exit_2_with_one_line(capsys):
    with pytest.raises(SystemExit) as exit_info:
        main(["run", "study.yaml"])
    assert exit_info.value.code == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--out" in err
    with pytest.raises(SystemExit) as exit_info:
        main(["simulate", "--speed", "fast"])
    assert exit_info.value.code == 2


def test_error_during_run_removes_the_work_folder(tmp_path, capsys, monkeypatch):
    def failing(context):
        raise UqgearError("samples: something the user got wrong")

    monkeypatch.setitem(analyses.ANALYSES, "monte_carlo", failing)
    out = tmp_path / "out"
    assert main(["run", str(write(tmp_path, TINY)), "--out", str(out), "--quiet"]) == 2
    assert capsys.readouterr().err == "uqgear: error: samples: something the user got wrong\n"
    assert not out.exists() and not leftovers(out)


def test_interrupted_run_keeps_its_work_and_resumes(tmp_path, capsys, monkeypatch):
    study = write(tmp_path, TINY)
    out = tmp_path / "out"
    calls = {"bifurcation": 0}
    original = analyses.ANALYSES["bifurcation"]

    def counting(context):
        calls["bifurcation"] += 1
        return original(context)

    def interrupted(context):
        raise KeyboardInterrupt

    monkeypatch.setitem(analyses.ANALYSES, "bifurcation", counting)
    monkeypatch.setitem(analyses.ANALYSES, "monte_carlo", interrupted)
    assert main(["run", str(study), "--out", str(out), "--quiet"]) == 130
    assert "run again with --resume" in capsys.readouterr().err
    partial = tmp_path / ".out.partial"
    assert (partial / "bifurcation.nc").is_file() and not out.exists()
    # without --resume a fresh run starts over; with it the finished analysis is reused
    monkeypatch.setitem(analyses.ANALYSES, "monte_carlo", analyses.monte_carlo_analysis)
    assert main(["run", str(study), "--out", str(out), "--quiet", "--resume"]) == 0
    assert calls["bifurcation"] == 1
    assert sorted(path.name for path in out.iterdir()) == ["bifurcation.nc", "monte_carlo.nc", "report.html"]
    assert not partial.exists()
    # a changed analysis is run again on resume, the unchanged one is not
    study.write_text(TINY.replace("samples: 4", "samples: 6"))
    assert main(["run", str(study), "--out", str(out), "--quiet", "--resume"]) == 0
    assert calls["bifurcation"] == 1
    assert load_result(out / "monte_carlo.nc").sizes["sample"] == 6


# ---------------------------------------------------------------------------- simulate and validate


def test_simulate_command_writes_a_figure_and_data(tmp_path):
    png = tmp_path / "run.png"
    completed = uqgear("simulate", "--speed", "3000", "--drive-torque", "1000", "--adhesion-torque", "30000",
                       "--n-periods", "120", "--keep-periods", "40", "--out", png)
    assert completed.returncode == 0, completed.stderr
    assert "pinion speed 3000 rpm, T1 1 kN m, T2 30 kN m" in completed.stdout
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_simulate_command_data_and_mistakes(tmp_path, capsys):
    data = tmp_path / "run.nc"
    assert main(["simulate", "--speed", "4000", "--n-periods", "80", "--keep-periods", "30",
                 "--out", str(data)]) == 0
    run = load_result(data)
    assert run.attrs["regime"].startswith(("period-", "quasi", "chaotic"))
    assert run.sizes["mesh_cycle"] == 30 * 64 and run.sizes["period"] == 30
    # the default adhesion torque balances the rated drive torque: T1 z2 / z1
    assert float(run["adhesion_torque"]) == pytest.approx(7000.0 * 101 / 21)
    capsys.readouterr()
    assert main(["simulate", "--speed", "3000", "--out", str(tmp_path / "run.txt")]) == 2
    assert "expected a file name ending in .png" in capsys.readouterr().err
    assert main(["simulate", "--speed", "-3000"]) == 2
    assert "--speed: expected a number in (0, 100000] rpm; got -3000" in capsys.readouterr().err
    assert main(["simulate", "--speed", "3000", "--design", "nowhere"]) == 2
    assert "not a bundled design" in capsys.readouterr().err
    assert not (tmp_path / "run.txt").exists()


def test_validate_command(capsys):
    assert main(["validate", str(SMOKE)]) == 0
    assert "valid study 'smoke' with 12 analyses" in capsys.readouterr().out


def test_report_command_on_a_folder_without_results(tmp_path, capsys):
    assert main(["report", str(tmp_path)]) == 2
    assert "no result files (*.nc)" in capsys.readouterr().err
    assert main(["report", str(tmp_path / "absent")]) == 2


# ---------------------------------------------------------------------------- determinism


def test_same_seed_gives_the_same_numbers():
    study = parse_study(TINY)
    spec = study.analyses[1]

    def once(seed_text: str) -> xr.Dataset:
        changed = parse_study(TINY.replace("seed: 5", seed_text))
        return running.run_analysis(changed, changed.analyses[1], runner=Runner(progress=False))

    first, second, other = once("seed: 5"), once("seed: 5"), once("seed: 6")
    assert spec.type == "monte_carlo"
    np.testing.assert_array_equal(first["input_adhesion_torque"], second["input_adhesion_torque"])
    np.testing.assert_array_equal(first["dte_rms_samples"], second["dte_rms_samples"])
    assert not np.array_equal(first["input_adhesion_torque"], other["input_adhesion_torque"])


# ---------------------------------------------------------------------------- rig data commands


@pytest.mark.parametrize("args, message", [
    (["synth-rig", "--out", "{tmp}/x.nc", "--effect", "eccentric:amplitude=1e-6"], "effect 'eccentric': unknown"),
    (["synth-rig", "--out", "{tmp}/x.nc", "--effect", "friction:coefficient=2"],
     r"friction.coefficient: expected a value in \[0, 0.3\]"),
    (["synth-rig", "--out", "{tmp}/x.nc", "--true", "k1"], "--true 'k1': expected KEY=VALUE"),
    (["synth-rig", "--out", "{tmp}/x.txt"], "expected a file name ending in .nc"),
    (["synth-rig", "--out", "{tmp}/missing/x.nc"], "does not exist"),
    (["calibrate", "{tmp}/none.nc", "--out", "{tmp}/cal"], "rig data file not found"),
])
def test_rig_commands_reject_bad_input(tmp_path, capsys, args, message):
    completed = _cli(capsys, *[a.format(tmp=tmp_path) for a in args])
    assert completed.returncode == 2
    assert message.replace("\\", "") in completed.stderr or __import__("re").search(message, completed.stderr)
    assert len(completed.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "x.nc").exists() and not (tmp_path / "cal").exists()


def test_calibrate_rejects_a_file_that_is_not_rig_data(tmp_path, capsys):
    import xarray as xr

    xr.Dataset({"a": ("t", [1.0])}).to_netcdf(tmp_path / "other.nc")
    completed = _cli(capsys, "calibrate", str(tmp_path / "other.nc"), "--out", str(tmp_path / "cal"))
    assert completed.returncode == 2
    assert "conventions" in completed.stderr
    assert not (tmp_path / "cal").exists()
    assert not any(p.name.startswith(".cal") for p in tmp_path.iterdir())


@pytest.mark.parametrize("words, message", [
    (["6", "x"], "uqgear: error: --pitch-classes: expected two ISO 1328-1 classes (e.g. 6 8) or none; got 6 x"),
    (["7"], "uqgear: error: --pitch-classes: expected two ISO 1328-1 classes (e.g. 6 8) or none; got 7"),
    (["9", "6"], "uqgear: error: pitch_classes: expected 1 <= lowest <= highest <= 11; got (9, 6)"),
])
@pytest.mark.parametrize("command", ["calibrate", "diagnose"])
def test_wrong_pitch_classes_are_rejected_before_any_work(tmp_path, capsys, words, message, command):
    rig = Path(__file__).resolve().parent.parent / "data" / "rig" / "healthy.nc"
    completed = _cli(capsys, command, str(rig), "--out", str(tmp_path / "out"), "--pitch-classes", *words)
    assert completed.returncode == 2
    assert completed.stderr.strip() == message
    assert not (tmp_path / "out").exists()
    assert not any(p.name.startswith(".out") for p in tmp_path.iterdir())


@pytest.mark.slow
def test_synth_rig_then_calibrate_recovers_the_truth(tmp_path, capsys):
    import json

    rig = tmp_path / "campaign.nc"
    made = _cli(capsys, "synth-rig", "--out", str(rig), "--true", "mesh_stiffness_scale=1.05", "--true", "k1=1.1e9",
                "--true", "zeta_mesh=0.06", "--seed", "4")
    assert made.returncode == 0, made.stderr
    done = _cli(capsys, "calibrate", str(rig), "--out", str(tmp_path / "cal"), "--params", "mesh_stiffness_scale",
                "zeta_mesh", "ste_amplitude", "k1", "k2")
    assert done.returncode == 0, done.stderr
    result = json.loads((tmp_path / "cal" / "calibration.json").read_text())
    assert result["converged"]
    truth = {"mesh_stiffness_scale": 1.05, "k1": 1.1e9, "zeta_mesh": 0.06, "ste_amplitude": 15e-6, "k2": 2e9}
    for name, value in truth.items():
        estimate = result["parameters"][name]
        assert estimate["q05"] <= value <= estimate["q95"], (name, estimate)
    assert {p.name for p in (tmp_path / "cal").iterdir()} == {"posterior.nc", "calibration.json", "report.html"}


@pytest.mark.parametrize("args, message", [
    (["diagnose", "{tmp}/none.nc", "--out", "{tmp}/d"], "rig data file not found"),
    (["diagnose", "{root}/data/rig/healthy.nc", "--out", "{tmp}/d", "--effects", "nonsense"],
     "'nonsense' is not a library effect"),
    (["blindtest", "--out", "{tmp}/d", "--n-per-effect", "0"], "--n-per-effect: expected a positive integer"),
    (["diagnose", "{root}/data/rig/healthy.nc", "--out", "{tmp}/d", "--workers", "0"],
     "workers: expected an integer >= 1; got 0"),
    (["blindtest", "--out", "{tmp}/d", "--workers", "0"], "workers: expected an integer >= 1; got 0"),
])
def test_diagnosis_commands_reject_bad_input(tmp_path, capsys, args, message):
    root = Path(__file__).resolve().parent.parent
    completed = _cli(capsys, *[a.format(tmp=tmp_path, root=root) for a in args])
    assert completed.returncode == 2
    assert message in completed.stderr
    assert len(completed.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "d").exists() and not any(p.name.startswith(".d") for p in tmp_path.iterdir())


# ---------------------------------------------------------------------------- bundled examples

def test_examples_lists_and_copies_the_bundled_studies(tmp_path, capsys):
    assert main(["examples"]) == 0
    listing = capsys.readouterr().out
    for name in ("smoke", "t2_envelope", "calibrate_healthy", "locomotive", "healthy", "eccentricity"):
        assert name in listing
    target = tmp_path / "mine.yaml"
    assert main(["examples", "copy", "calibrate_healthy", str(target)]) == 0
    assert target.read_text() == (STUDIES / "calibrate_healthy.yaml").read_text()
    # the copy still finds its rig campaign by name, wherever it is
    assert main(["validate", str(target)]) == 0
    capsys.readouterr()
    assert main(["examples", "copy", "calibrate_healthy", str(target)]) == 2
    assert "pass --force" in capsys.readouterr().err
    assert main(["examples", "copy", "calibrate_healthy", str(target), "--force"]) == 0
    assert main(["examples", "copy", "no_such_study", str(tmp_path)]) == 2
    assert "not a bundled study" in capsys.readouterr().err
    assert main(["examples", "copy", "smoke", str(tmp_path)]) == 0
    assert (tmp_path / "smoke.yaml").is_file()


@pytest.mark.slow
def test_a_bundled_study_runs_by_name_into_a_new_nested_folder(smoke_run):
    # the module's smoke run: "smoke" by name, into results/deeper/smoke relative to an empty folder
    assert smoke_run.relative_to(smoke_run.parents[2]) == Path("results") / "deeper" / "smoke"
    assert (smoke_run / "report.html").is_file()
    assert sorted(path.name for path in smoke_run.parents[2].iterdir()) == ["results"]


def test_no_output_folders_are_left_behind_by_an_invalid_study(tmp_path, capsys):
    bad = tmp_path / "bad.yaml"
    bad.write_text((STUDIES / "smoke.yaml").read_text().replace("n_periods: 100", "n_periods: -3"))
    assert main(["run", str(bad), "--out", str(tmp_path / "new" / "out")]) == 2
    assert "n_periods" in capsys.readouterr().err
    assert not (tmp_path / "new").exists()
    # below a file there is no folder to make
    (tmp_path / "file").write_text("x")
    assert main(["run", "smoke", "--out", str(tmp_path / "file" / "out")]) == 2
    assert "is a file, not a folder" in capsys.readouterr().err
