"""Atomic file output: nothing half-written is ever left under a final name.

Every writer in uqgear (netCDF results, rig files, HTML reports) writes to a
temporary name in the target's folder and renames it into place once the
content is complete; on any error the temporary file is removed and an
existing target is left untouched.
"""

from __future__ import annotations

import contextlib
import os
import tempfile
from collections.abc import Iterator
from pathlib import Path


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


@contextlib.contextmanager
def atomic_path(target: str | os.PathLike[str]) -> Iterator[Path]:
    """Yield a temporary path next to ``target``; rename it to ``target`` on success.

    The file gets the permissions an ordinary new file would (``0o666`` less
    the umask; ``mkstemp`` alone makes it private) and is flushed to disk
    before the rename, so the final name never points at partial content.
    """
    target = Path(target)
    handle, name = tempfile.mkstemp(dir=target.parent, prefix=f".{target.name}.", suffix=".partial")
    os.close(handle)
    temporary = Path(name)
    try:
        yield temporary
        os.chmod(temporary, 0o666 & ~_umask())
        with open(temporary, "rb") as written:
            os.fsync(written.fileno())
        os.replace(temporary, target)
    finally:
        if temporary.exists():
            temporary.unlink()


def write_text_atomic(target: str | os.PathLike[str], text: str) -> Path:
    """Write a text file atomically (UTF-8)."""
    with atomic_path(target) as temporary:
        temporary.write_text(text, encoding="utf-8")
    return Path(target)


__all__ = ["atomic_path", "write_text_atomic"]
