"""Output folders written as a whole (uqgear.common.transaction), for the command line and the Python API alike.

Checked on real folders: a finished block publishes its files under the
final name and nothing beside it; a user mistake leaves nothing, not even
the parent folders it made; an internal failure publishes what was finished
and says where; a resumable run keeps its work folder; an earlier run's
files are merged or replaced as asked; and uqgear.calibrate and
uqgear.diagnose leave nothing behind for a mistake in their input.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from uqgear.common.errors import InternalError, UqgearError
from uqgear.common.transaction import OutputFolder, partial_folder


def _listing(root: Path) -> list[str]:
    return sorted(str(path.relative_to(root)) for path in root.rglob("*"))


def test_a_finished_block_publishes_its_folder_and_nothing_else(tmp_path):
    out = tmp_path / "made" / "here" / "out"
    with OutputFolder(out) as work:
        assert work == partial_folder(out) == out.parent / ".out.partial"
        (work / "a.txt").write_text("a")
        assert not out.exists()
    assert _listing(tmp_path) == ["made", "made/here", "made/here/out", "made/here/out/a.txt"]


def test_a_user_mistake_leaves_nothing_not_even_the_parents_it_made(tmp_path):
    out = tmp_path / "made" / "out"
    with pytest.raises(UqgearError, match="bad input"):
        with OutputFolder(out) as work:
            (work / "a.txt").write_text("a")
            raise UqgearError("bad input")
    assert _listing(tmp_path) == []


def test_an_internal_failure_publishes_what_was_finished_and_says_where(tmp_path):
    out = tmp_path / "out"
    with pytest.raises(InternalError) as caught:
        with OutputFolder(out) as work:
            (work / "finished.nc").write_text("done")
            raise InternalError("fit", ZeroDivisionError("float division by zero"))
    assert caught.value.kept == str(out) and _listing(out) == ["finished.nc"]
    # with nothing finished, nothing is published
    with pytest.raises(InternalError) as caught:
        with OutputFolder(tmp_path / "empty"):
            raise InternalError("fit", ZeroDivisionError("float division by zero"))
    assert caught.value.kept is None and not (tmp_path / "empty").exists()


def test_a_resumable_run_keeps_its_work_folder_for_resume(tmp_path):
    out = tmp_path / "out"
    folder = OutputFolder(out, resumable=True)
    with pytest.raises(KeyboardInterrupt):
        with folder as work:
            (work / "chunk.nc").write_text("1")
            raise KeyboardInterrupt
    assert (folder.work / "chunk.nc").is_file() and not out.exists()
    with pytest.raises(InternalError) as caught:
        with OutputFolder(out, resumable=True, resume=True) as work:
            assert (work / "chunk.nc").is_file()          # resumed where it stopped
            raise InternalError("fit", ValueError("x"))
    assert "--resume" in caught.value.kept and folder.work.is_dir()
    # a fresh run starts over
    with OutputFolder(out, resumable=True) as work:
        assert not (work / "chunk.nc").exists()
    assert out.is_dir() and not folder.work.exists()


def test_an_earlier_runs_files_are_refused_merged_or_replaced(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    (out / "old.txt").write_text("old")
    (out / "shared.txt").write_text("old")
    with pytest.raises(UqgearError, match="--out .*out: exists and is not an empty folder"):
        OutputFolder(out, where="--out", existing="refuse").check()
    with OutputFolder(out, existing="merge") as work:
        (work / "shared.txt").write_text("new")
        (work / "sub").mkdir()
        (work / "sub" / "x").write_text("x")
    assert _listing(out) == ["old.txt", "shared.txt", "sub", "sub/x"] and (out / "shared.txt").read_text() == "new"
    with OutputFolder(out, existing="replace") as work:
        (work / "only.txt").write_text("new")
    assert _listing(out) == ["only.txt"]
    (tmp_path / "file").write_text("f")
    with pytest.raises(UqgearError, match="exists and is not a folder"):
        OutputFolder(tmp_path / "file").check()
    with pytest.raises(UqgearError, match="is a file, not a folder"):
        OutputFolder(tmp_path / "file" / "below").check()


def test_the_python_api_leaves_nothing_for_a_mistake_in_its_input(tmp_path):
    import uqgear

    broken = tmp_path / "broken.nc"
    broken.write_text("not a netCDF file")
    for call in (uqgear.diagnose, uqgear.calibrate):
        out = tmp_path / "deep" / call.__name__
        with pytest.raises(UqgearError, match="broken.nc"):
            call(broken, out)
        assert not (tmp_path / "deep").exists()
    assert _listing(tmp_path) == ["broken.nc"]


def test_a_python_study_run_is_published_whole_and_kept_for_resume_on_failure(tmp_path, monkeypatch):
    """uqgear.run_study as the command's run: a failed analysis leaves no result folder, its work resumable."""
    from test_cli import TINY

    from uqgear import parse_study, run_study
    from uqgear.common.errors import internal_step
    from uqgear.study import analyses

    study = parse_study(TINY)
    real = analyses.ANALYSES["monte_carlo"]

    def failing(context):
        with internal_step("sample"):
            raise ValueError("array must not contain infs or NaNs")

    monkeypatch.setitem(analyses.ANALYSES, "monte_carlo", failing)
    out = tmp_path / "out"
    with pytest.raises(InternalError) as caught:
        run_study(study, out, show_progress=False)
    assert not out.exists() and "--resume" in caught.value.kept
    assert (partial_folder(out) / "bifurcation.nc").is_file()
    monkeypatch.setitem(analyses.ANALYSES, "monte_carlo", real)
    written = run_study(study, out, show_progress=False, resume=True)
    assert [path.name for path in written] == ["bifurcation.nc", "monte_carlo.nc"]
    assert _listing(out) == ["bifurcation.nc", "monte_carlo.nc"] and not partial_folder(out).exists()
