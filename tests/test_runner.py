"""Tests of the chunked runner (in-process and on a loopback dask cluster) and of progress bars."""

from __future__ import annotations

import io
import logging
import os
import socket
import sys
import uuid
from pathlib import Path

import numpy as np
import pytest
import xarray as xr

from uqgear.common.errors import DesignError, ExecutionError
from uqgear.common.progress import progress
from uqgear.uq.runner import Runner, chunk_hash

N_SAMPLES = 23
TIME = np.linspace(0.0, 1.0, 5)
#: Sample index holding the point (pi/2, pi/2, 1), where the Ishigami function is 1 + 7 + 0.1.
KNOWN_SAMPLE = 10


# ----------------------------------------------------------------------------- models
# Module-level so that dask can pickle them by reference to the worker processes.


def ishigami_model(samples: xr.Dataset) -> xr.Dataset:
    """Ishigami function (a=7, b=0.1) with a few extra outputs of other dtypes and dims."""
    x1, x2, x3 = samples["x1"], samples["x2"], samples["x3"]
    y = np.sin(x1) + 7.0 * np.sin(x2) ** 2 + 0.1 * x3 ** 4 * np.sin(x1)
    wave = (y * xr.DataArray(np.cos(2 * np.pi * TIME), dims="time")).transpose("sample", "time")
    return xr.Dataset(
        {
            "y": y.assign_attrs(units="1"),
            "wave": wave.assign_attrs(units="m"),
            "above_five": (y > 5.0).astype(np.int8),
            "level": xr.where(y > 5.0, "high", "low"),
            "window": ("time", np.hanning(TIME.size)),
        },
        coords={"time": ("time", TIME, {"units": "s"})},
        attrs={"model": "ishigami", "a": 7.0, "b": 0.1},
    )


def _record_call(count_dir: Path, chunk: xr.Dataset) -> int:
    """Leave one file per call (works across processes); returns the number of calls so far."""
    count_dir.mkdir(exist_ok=True)
    first = int(chunk["sample"].values[0])
    (count_dir / f"{first:04d}-{os.getpid()}-{uuid.uuid4().hex}").touch()
    return len(list(count_dir.iterdir()))


def _calls(count_dir: Path) -> list[str]:
    return sorted(path.name for path in count_dir.iterdir()) if count_dir.exists() else []


class SimulatedKill(BaseException):
    """Stands in for a killed process: like KeyboardInterrupt it is no Exception."""


class CountingModel:
    """Ishigami model counting its calls; optionally 'killed' after a number of calls."""

    def __init__(self, count_dir: Path, kill_after: int | None = None) -> None:
        self.count_dir = count_dir
        self.kill_after = kill_after

    def __call__(self, samples: xr.Dataset) -> xr.Dataset:
        calls = _record_call(self.count_dir, samples)
        if self.kill_after is not None and calls > self.kill_after:
            raise SimulatedKill(f"killed at call {calls}")
        return ishigami_model(samples)


class FailingModel:
    """Ishigami model that raises on the chunk holding one sample, the first ``failures`` times."""

    def __init__(self, count_dir: Path, bad_sample: int, failures: int = 1_000_000,
                 error: type[Exception] = RuntimeError) -> None:
        self.count_dir = count_dir
        self.bad_sample = bad_sample
        self.failures = failures
        self.error = error

    def __call__(self, samples: xr.Dataset) -> xr.Dataset:
        if self.bad_sample in samples["sample"].values:
            attempt = _record_call(self.count_dir, samples)
            if attempt <= self.failures:
                raise self.error(f"solver diverged at sample {self.bad_sample}")
        return ishigami_model(samples)


def wrong_length_model(samples: xr.Dataset) -> xr.Dataset:
    return ishigami_model(samples).isel(sample=slice(0, 1))


# ----------------------------------------------------------------------------- fixtures


@pytest.fixture(scope="module")
def samples() -> xr.Dataset:
    rng = np.random.default_rng(np.random.SeedSequence(20240611))
    values = rng.uniform(-np.pi, np.pi, size=(3, N_SAMPLES))
    values[:, KNOWN_SAMPLE] = [np.pi / 2, np.pi / 2, 1.0]
    return xr.Dataset(
        {name: ("sample", values[row], {"units": "rad"})
         for row, name in enumerate(("x1", "x2", "x3"))},
        coords={"sample": np.arange(N_SAMPLES)},
        attrs={"design_name": "test"},
    )


@pytest.fixture(scope="module")
def reference(samples: xr.Dataset) -> xr.Dataset:
    """The model evaluated in a single call, without the runner."""
    return ishigami_model(samples)


@pytest.fixture(scope="module")
def cluster():
    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  host="127.0.0.1", dashboard_address=None,
                                  silence_logs=logging.ERROR) as local_cluster:
        yield local_cluster


def _free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


# ----------------------------------------------------------------------------- in-process


def test_reference_model_matches_closed_form(reference: xr.Dataset) -> None:
    # independent anchor: Ishigami(pi/2, pi/2, 1) = sin + 7 sin^2 + 0.1 * 1 * sin = 8.1
    assert reference["y"].sel(sample=KNOWN_SAMPLE).item() == pytest.approx(8.1, abs=1e-12)


@pytest.mark.parametrize("chunk_size", [1, 7, N_SAMPLES, 1000])
def test_in_process_result_does_not_depend_on_chunk_size(samples, reference, chunk_size):
    runner = Runner(chunk_size, progress=False)
    result = runner.run(ishigami_model, samples)
    xr.testing.assert_identical(result, reference)
    assert result["above_five"].dtype == np.int8
    assert runner.last_report.n_chunks == -(-N_SAMPLES // chunk_size)
    assert runner.last_report.executor == "in-process"


def test_model_does_not_change_the_callers_samples(samples):
    before = samples.copy(deep=True)

    def scribbling_model(chunk: xr.Dataset) -> xr.Dataset:
        chunk["x1"].values[:] = 0.0
        return ishigami_model(chunk)

    Runner(5, progress=False).run(scribbling_model, samples)
    xr.testing.assert_identical(samples, before)


def test_kill_and_resume_reuses_finished_chunks(samples, reference, tmp_path, caplog):
    checkpoints = tmp_path / "checkpoints"
    runner = Runner(5, checkpoint_dir=checkpoints, progress=False)
    key = "study: test\nanalysis: monte_carlo"

    with pytest.raises(SimulatedKill):
        runner.run(CountingModel(tmp_path / "first", kill_after=2), samples, key=key)
    assert len(_calls(tmp_path / "first")) == 3
    assert len(list(checkpoints.glob("chunk-*.nc"))) == 2
    assert not list(checkpoints.glob(".*"))  # no temporary files left behind

    with caplog.at_level(logging.INFO, logger="uqgear.uq.runner"):
        result = runner.run(CountingModel(tmp_path / "second"), samples, key=key, resume=True)
    # 5 chunks of which the first 2 finished before the kill: only chunks 2, 3, 4 run again
    assert [name[:4] for name in _calls(tmp_path / "second")] == ["0010", "0015", "0020"]
    assert runner.last_report.reused_chunks == 2
    assert runner.last_report.evaluated_chunks == 3
    assert "2 of 5 chunks reused" in caplog.text
    xr.testing.assert_identical(result, reference)
    for name in ("y", "wave"):
        assert result[name].values.tobytes() == reference[name].values.tobytes()


def test_stale_checkpoints_are_not_reused(samples, reference, tmp_path):
    checkpoints = tmp_path / "checkpoints"
    runner = Runner(5, checkpoint_dir=checkpoints, progress=False)
    # the checkpoint hash includes the model's name: all runs use the same model class
    runner.run(CountingModel(tmp_path / "initial"), samples, key="study A")

    runner.run(CountingModel(tmp_path / "other_key"), samples, key="study B", resume=True)
    assert len(_calls(tmp_path / "other_key")) == 5

    changed = samples.copy(deep=True)
    changed["x3"].values[12] += 1e-9
    result = runner.run(CountingModel(tmp_path / "changed"), changed, key="study A", resume=True)
    assert [name[:4] for name in _calls(tmp_path / "changed")] == ["0010"]
    xr.testing.assert_identical(result, ishigami_model(changed))

    runner.run(CountingModel(tmp_path / "same"), samples, key="study A", resume=True)
    assert _calls(tmp_path / "same") == []


def test_unreadable_checkpoint_is_evaluated_again(samples, reference, tmp_path, caplog):
    checkpoints = tmp_path / "checkpoints"
    runner = Runner(10, checkpoint_dir=checkpoints, progress=False)
    runner.run(CountingModel(tmp_path / "initial"), samples, key="k")
    broken = sorted(checkpoints.glob("chunk-*.nc"))[1]
    broken.write_text("not netCDF")
    with caplog.at_level(logging.WARNING, logger="uqgear.uq.runner"):
        result = runner.run(CountingModel(tmp_path / "calls"), samples, key="k", resume=True)
    assert len(_calls(tmp_path / "calls")) == 1
    assert "unusable" in caplog.text and broken.name in caplog.text
    xr.testing.assert_identical(result, reference)


def test_failing_chunk_is_retried_then_fails_naming_chunk(samples, tmp_path):
    model = FailingModel(tmp_path / "attempts", bad_sample=KNOWN_SAMPLE)
    runner = Runner(7, retries=2, progress=False)
    with pytest.raises(ExecutionError,
                       match=r"chunk 1 \(samples 7 to 13\) failed after 3 attempts: "
                             r"RuntimeError: solver diverged at sample 10"):
        runner.run(model, samples)
    assert len(_calls(tmp_path / "attempts")) == 3


def test_flaky_chunk_succeeds_on_retry(samples, reference, tmp_path):
    model = FailingModel(tmp_path / "attempts", bad_sample=KNOWN_SAMPLE, failures=1)
    runner = Runner(7, retries=2, progress=False)
    xr.testing.assert_identical(runner.run(model, samples), reference)
    assert runner.last_report.retried_attempts == 1


def test_user_error_from_model_is_not_retried(samples, tmp_path):
    model = FailingModel(tmp_path / "attempts", bad_sample=0, error=DesignError)
    with pytest.raises(DesignError, match="solver diverged at sample 0"):
        Runner(7, retries=2, progress=False).run(model, samples)
    assert len(_calls(tmp_path / "attempts")) == 1


def test_model_returning_wrong_sample_length_is_reported(samples):
    with pytest.raises(ExecutionError, match=r"chunk 0: .*sample length 1; expected dim 'sample' "
                                             r"of length 7"):
        Runner(7, progress=False).run(wrong_length_model, samples)


def test_model_returning_no_dataset_is_reported(samples):
    with pytest.raises(ExecutionError, match="chunk 0: the model returned DataArray; expected an "
                                             "xarray Dataset"):
        Runner(7, progress=False).run(lambda chunk: chunk["x1"], samples)


@pytest.mark.parametrize(
    ("options", "message"),
    [
        ({"chunk_size": 0}, r"chunk_size: expected a positive integer; got 0"),
        ({"chunk_size": 2.5}, r"chunk_size: expected a positive integer; got 2.5"),
        ({"retries": -1}, r"retries: expected a non-negative integer; got -1"),
        ({"workers": 4}, r"workers: expected None or 1 without a scheduler"),
        ({"scheduler": 8786}, r"scheduler: expected None, an address like 'tcp://host:8786' or "
                              r"a distributed.Client; got int"),
        ({"scheduler": " "}, r"scheduler: expected an address"),
        ({"connect_timeout": 0}, r"connect_timeout: expected a positive number"),
    ],
)
def test_bad_runner_options_are_rejected(options, message):
    with pytest.raises(ExecutionError, match=message):
        Runner(**options)


def test_bad_run_arguments_are_rejected(samples):
    runner = Runner(5, progress=False)
    with pytest.raises(ExecutionError, match=r"samples: expected an xarray Dataset with dim "
                                             r"'sample'; got a Dataset with dims \('point',\)"):
        runner.run(ishigami_model, samples.rename(sample="point"))
    with pytest.raises(ExecutionError, match="samples: expected at least one sample"):
        runner.run(ishigami_model, samples.isel(sample=slice(0, 0)))
    with pytest.raises(ExecutionError, match="evaluate: expected a callable model"):
        runner.run("ishigami", samples)
    with pytest.raises(ExecutionError, match="resume: expected a checkpoint_dir"):
        runner.run(ishigami_model, samples, resume=True)


def test_chunk_hash_follows_values_and_key_not_string_dtype(samples):
    chunk = samples.isel(sample=slice(0, 5)).assign(label=("sample", list("abcde")))
    as_objects = chunk.assign(label=("sample", np.array(list("abcde"), dtype=object)))
    assert chunk_hash(chunk, "k", ishigami_model) == chunk_hash(as_objects, "k", ishigami_model)
    assert chunk_hash(chunk, "k", ishigami_model) != chunk_hash(chunk, "k2", ishigami_model)
    assert chunk_hash(chunk, "k", ishigami_model) != chunk_hash(chunk, "k", wrong_length_model)
    nudged = chunk.copy(deep=True)
    nudged["x1"].values[4] = np.nextafter(nudged["x1"].values[4], 10.0)
    assert chunk_hash(chunk, "k", ishigami_model) != chunk_hash(nudged, "k", ishigami_model)


# ----------------------------------------------------------------------------- dask cluster


def test_unreachable_scheduler_is_reported(samples):
    address = f"tcp://127.0.0.1:{_free_port()}"
    runner = Runner(7, scheduler=address, connect_timeout=1.0, progress=False)
    with pytest.raises(ExecutionError,
                       match=rf"scheduler {address}: cannot connect within 1 s .*expected a "
                             rf"running dask scheduler"):
        runner.run(ishigami_model, samples)


def test_one_and_two_cluster_workers_give_bit_identical_results(cluster, samples, reference,
                                                                tmp_path):
    address = cluster.scheduler_address
    results = {}
    for workers in (1, 2):
        model = CountingModel(tmp_path / f"workers-{workers}")
        runner = Runner(7, scheduler=address, workers=workers, progress=False)
        results[workers] = runner.run(model, samples)
        assert runner.last_report.executor == address
        assert len(_calls(tmp_path / f"workers-{workers}")) == 4
    # with workers=1 every chunk ran in one and the same worker process
    assert len({name.split("-")[1] for name in _calls(tmp_path / "workers-1")}) == 1
    assert {name.split("-")[1] for name in _calls(tmp_path / "workers-1")} != {str(os.getpid())}
    for workers in (1, 2):
        xr.testing.assert_identical(results[workers], reference)
        for name in ("y", "wave", "above_five"):
            assert results[workers][name].values.tobytes() == results[1][name].values.tobytes()


def test_cluster_checkpoints_resume_in_process(cluster, samples, reference, tmp_path):
    from distributed import Client

    checkpoints = tmp_path / "checkpoints"
    with Client(cluster.scheduler_address, set_as_default=False) as client:
        on_cluster = Runner(5, scheduler=client, checkpoint_dir=checkpoints, progress=False)
        result = on_cluster.run(CountingModel(tmp_path / "cluster-calls"), samples, key="k")
        assert client.status == "running"  # a client passed in is left open
    xr.testing.assert_identical(result, reference)
    local = Runner(5, checkpoint_dir=checkpoints, progress=False)
    resumed = local.run(CountingModel(tmp_path / "calls"), samples, key="k", resume=True)
    assert _calls(tmp_path / "calls") == []
    xr.testing.assert_identical(resumed, reference)


def test_failing_chunk_on_cluster_is_retried_then_fails(cluster, samples, tmp_path):
    model = FailingModel(tmp_path / "attempts", bad_sample=KNOWN_SAMPLE)
    runner = Runner(7, scheduler=cluster.scheduler_address, retries=2, progress=False)
    with pytest.raises(ExecutionError,
                       match=r"chunk 1 \(samples 7 to 13\) failed after 3 attempts: "
                             r"RuntimeError: solver diverged at sample 10"):
        runner.run(model, samples)
    assert len(_calls(tmp_path / "attempts")) == 3


def test_more_workers_than_the_cluster_has_is_reported(cluster, samples):
    runner = Runner(7, scheduler=cluster.scheduler_address, workers=3, connect_timeout=0.5,
                    progress=False)
    with pytest.raises(ExecutionError, match=r"workers: expected at least 3 workers at scheduler "
                                             r"tcp://127.0.0.1:\d+; 2 connected"):
        runner.run(ishigami_model, samples)


# ----------------------------------------------------------------------------- progress


def test_progress_is_silent_without_terminal(monkeypatch):
    monkeypatch.delenv("UQGEAR_PROGRESS", raising=False)
    monkeypatch.setattr(sys, "stderr", io.StringIO())
    bar = progress(range(4), desc="chunks", unit="chunk")
    assert bar.disable
    assert list(bar) == [0, 1, 2, 3]
    assert sys.stderr.getvalue() == ""


def test_progress_environment_variable_overrides_detection(monkeypatch):
    monkeypatch.setattr(sys, "stderr", io.StringIO())
    monkeypatch.setenv("UQGEAR_PROGRESS", "1")
    with progress(10, desc="evaluating", unit="sample") as bar:
        assert not bar.disable
        bar.update(10)
    assert "evaluating" in sys.stderr.getvalue() and "10/10" in sys.stderr.getvalue()
    with progress(10, desc="evaluating", unit="sample", enabled=False) as bar:
        assert bar.disable
    monkeypatch.setenv("UQGEAR_PROGRESS", "0")
    monkeypatch.setattr(sys.stderr, "isatty", lambda: True)
    with progress(10, desc="evaluating", unit="sample") as bar:
        assert bar.disable
