"""Output folders written as a whole: work in a hidden sibling folder, publish it when everything is written.

A command that writes several files (a diagnosis, a calibration, a blind
test, a study run) must never leave half of them behind. Its files are
written into ``.NAME.partial`` next to the output folder ``NAME`` and the
work folder is renamed into place once the last file is written. A user
mistake found on the way (a bad option, a file in the wrong format) removes
the work folder and any folder made above it, so nothing is left. An
internal failure after the input was accepted publishes what was finished
(with ``failure.json``, written by the caller) and says so on the error
(:attr:`~uqgear.common.errors.InternalError.kept`). A resumable run (a study)
keeps its work folder instead, with its checkpoints, for ``--resume``.

Examples
--------
>>> import tempfile, pathlib
>>> root = pathlib.Path(tempfile.mkdtemp())
>>> with OutputFolder(root / "results") as work:
...     _ = (work / "summary.txt").write_text("done")
>>> sorted(path.name for path in (root / "results").iterdir())
['summary.txt']
"""

from __future__ import annotations

import os
import shutil
import tempfile
from collections.abc import Sequence
from pathlib import Path
from types import TracebackType
from typing import Literal

from .errors import InternalError, UqgearError

#: Suffix of the hidden work folder beside an output folder.
PARTIAL_SUFFIX = ".partial"

#: What to do with an output folder that already holds files: ``refuse`` (a user mistake), ``replace``
#: (the whole folder, by the finished one) or ``merge`` (each finished file replaces its namesake).
Existing = Literal["refuse", "replace", "merge"]


def partial_folder(out: str | os.PathLike[str]) -> Path:
    """The hidden work folder of an output folder: ``.NAME.partial`` beside it."""
    path = Path(out)
    return path.parent / f".{path.name}{PARTIAL_SUFFIX}"


def is_empty_folder(path: Path) -> bool:
    """Whether ``path`` is a folder without any entry."""
    return path.is_dir() and not any(path.iterdir())


def check_parents(out: Path, where: str) -> None:
    """Refuse an output path below a file (its missing folders are made once the input is valid)."""
    for ancestor in out.absolute().parents:
        if ancestor.exists():
            if not ancestor.is_dir():
                raise UqgearError(f"{where} {out}: {ancestor} is a file, not a folder")
            return


def make_parents(out: Path) -> list[Path]:
    """Create the missing folders above ``out``; return them, outermost first."""
    missing = []
    folder = out.absolute().parent
    while not folder.exists():
        missing.append(folder)
        folder = folder.parent
    missing.reverse()
    for folder in missing:
        folder.mkdir()
    return missing


def remove_if_empty(folders: Sequence[Path]) -> None:
    """Remove folders made by :func:`make_parents` again, innermost first, while empty."""
    for folder in reversed(folders):
        try:
            folder.rmdir()
        except OSError:
            return


def publish(work: Path, out: Path, *, merge: bool = False) -> None:
    """Move a finished work folder to ``out``.

    An empty ``out`` is replaced. A folder with files is replaced as a whole,
    or with ``merge`` each entry of ``work`` replaces its namesake in it
    (other files stay). The old content is moved aside first and removed
    after, so ``out`` never holds a mix of half-replaced entries.
    """
    if out.exists() and is_empty_folder(out):
        out.rmdir()
    if not out.exists():
        work.rename(out)
        return
    if not merge:
        _swap(work, out)
        return
    for item in sorted(work.iterdir()):
        target = out / item.name
        if target.is_dir() and not target.is_symlink():
            _swap(item, target)
        else:
            os.replace(item, target)
    work.rmdir()


def _swap(new: Path, old: Path) -> None:
    """Put ``new`` in the place of the existing ``old``, then remove the old content."""
    aside = Path(tempfile.mkdtemp(prefix=f".{old.name}.old-", dir=old.parent))
    aside.rmdir()
    old.rename(aside)
    new.rename(old)
    if aside.is_dir():
        shutil.rmtree(aside, ignore_errors=True)
    else:
        aside.unlink()


class OutputFolder:
    """A context manager yielding the work folder of ``out``; ``out`` appears only once the block succeeds.

    Parameters
    ----------
    out : path
        The output folder.
    where : str
        How messages name it (``--out`` on the command line, ``out_dir`` in Python).
    existing : {"refuse", "replace", "merge"}
        What an ``out`` that already holds files gets: refused as a user
        mistake before any work, replaced as a whole once the new one is
        finished, or merged (each finished file replaces its namesake).
    resumable : bool
        A work folder left by an interrupted run is kept for ``resume``
        (reused) or removed (a fresh run), and on an internal failure or an
        interruption the work folder stays, with its checkpoints, instead of
        being published.
    resume : bool
        With ``resumable``: continue in the work folder an earlier run left.

    Raises
    ------
    UqgearError
        On entering: ``out`` is a file, or holds files and ``existing`` is
        ``refuse``, or lies below a file.
    """

    def __init__(
        self,
        out: str | os.PathLike[str],
        *,
        where: str = "out_dir",
        existing: Existing = "merge",
        resumable: bool = False,
        resume: bool = False,
    ) -> None:
        self.out = Path(out)
        self.where = where
        self.existing = existing
        self.resumable = resumable
        self.resume = resume
        self.work = partial_folder(self.out)
        self._parents: list[Path] = []
        self._created = False

    def check(self) -> None:
        """Refuse an output path that cannot be written (before any work starts)."""
        out = self.out
        if out.exists() and not out.is_dir():
            raise UqgearError(f"{self.where} {out}: exists and is not a folder; expected a new or empty folder")
        if self.existing == "refuse" and out.is_dir() and not is_empty_folder(out):
            raise UqgearError(f"{self.where} {out}: exists and is not an empty folder; choose a new folder")
        check_parents(out, self.where)

    def __enter__(self) -> Path:
        self.check()
        self._parents = make_parents(self.out)
        if self.work.exists() and not (self.resumable and self.resume):
            # left by an interrupted run; a fresh one was asked for
            shutil.rmtree(self.work)
        if not self.work.exists():
            self.work.mkdir()
            self._created = True
        return self.work

    def __exit__(
        self, kind: type[BaseException] | None, error: BaseException | None, trace: TracebackType | None
    ) -> None:
        if error is None:
            publish(self.work, self.out, merge=self.existing == "merge")
            return
        if isinstance(error, InternalError):
            self._keep_finished(error)
        elif self.resumable and isinstance(error, KeyboardInterrupt):
            return  # the work folder stays for --resume
        else:
            # a mistake in the input (or an interruption): nothing this run made is left
            if self._created or not self.resumable:
                shutil.rmtree(self.work, ignore_errors=True)
            remove_if_empty(self._parents)

    def _keep_finished(self, error: InternalError) -> None:
        """The input was valid and work was done: what was finished is kept, not thrown away."""
        if self.resumable:
            error.kept = f"{self.work} (run again with --resume to continue)"
        elif any(self.work.iterdir()):
            publish(self.work, self.out, merge=self.existing == "merge")
            error.kept = str(self.out)
        else:
            self.work.rmdir()
            remove_if_empty(self._parents)


__all__ = [
    "PARTIAL_SUFFIX",
    "OutputFolder",
    "partial_folder",
    "publish",
    "is_empty_folder",
    "check_parents",
    "make_parents",
    "remove_if_empty",
]
